"""A signal is never lost: one that lands where Python cannot raise it (a garbage-collection
callback, as JAX's), or one swallowed by a library, still stops the command with 130/143;
a later signal during the teardown ends the process with the same status, not the default
action's. Real child processes, real signals."""

import signal
import subprocess
import sys
import textwrap
import time

from helpers import start_child

# The child runs the real command line (its own process: the entry point's handlers and
# exit), with one stage replaced by ``body``.
_CHILD = """
import gc, os, signal, sys, time
import whiskerid.{module} as m

def stage(*args, **kwargs):
    print("STAGE", file=sys.stderr, flush=True)
{body}

m.{name} = stage
from whiskerid.cli._main import main
sys.argv = ["whiskerid", *sys.argv[1:]]
sys.exit(main())
"""

# The signal sent from inside a gc callback: the handler runs there, and its exception is
# only reported ("Exception ignored in ... gc callback").
IN_GC_CALLBACK = """
    def callback(phase, info):
        if phase == "start":
            gc.callbacks.remove(callback)
            os.kill(os.getpid(), signal.{sig})
    gc.callbacks.append(callback)
    gc.collect()
    for _ in range(1000):  # 10 s of work that a raised interrupt stops
        time.sleep(0.01)
"""

# A library that catches KeyboardInterrupt and carries on.
SWALLOWED = """
    try:
        os.kill(os.getpid(), signal.{sig})
        time.sleep(0.5)
    except KeyboardInterrupt:
        pass
"""


def _run(stage: str, body: str, sig: str, argv: list[str]) -> tuple[int, str, float]:
    """Status, stderr, and seconds from the stage's start to the child's exit."""
    module, name = stage.rsplit(".", 1)
    body = textwrap.indent(textwrap.dedent(body.format(sig=sig)), "    ")
    script = _CHILD.format(module=module, name=name, body=body)
    child, before, _ = start_child(script, argv, "STAGE")
    t0 = time.perf_counter()
    err = child.stderr.read()  # the same buffered reader (communicate would skip its buffer)
    child.wait(timeout=60)
    child.stdout.close()
    child.stderr.close()
    return child.returncode, "".join(before) + err, time.perf_counter() - t0


def test_a_signal_in_a_gc_callback_still_stops_the_command_at_once(tmp_path):
    status, err, took = _run("terrain.synthesize_dataset", IN_GC_CALLBACK, "SIGTERM",
                             ["dataset", "synth", "--out", str(tmp_path / "ds")])  # fmt: skip
    assert status == 143, err
    assert "interrupted (SIGTERM)" in err and "Traceback" not in err
    assert "Exception ignored" not in err
    assert took < 5  # the 10 s stage was cut short


def test_a_swallowed_signal_still_sets_the_exit_status(tmp_path):
    """The command ran to its end (the library ate the interrupt): its output is complete,
    and the status says it was interrupted."""
    csv = tmp_path / "s.csv"
    status, err, _ = _run("plot.plot_signal_and_spectrum", SWALLOWED, "SIGINT",
                          ["simulate", "--duration", "0.5", "--plot", str(tmp_path / "p.png"),
                           "--out", str(csv)])  # fmt: skip
    assert status == 130, err
    assert "interrupted (SIGINT); kept (complete)" in err and csv.exists()


def test_a_second_signal_during_the_teardown_exits_with_the_first_status(tmp_path):
    """After the report line the process ends at once, without the interpreter's teardown
    (here an exit handler that would take 10 s); a SIGTERM that comes then does not turn
    the status into the default action's (-15): it stays the first signal's."""
    body = """
    import atexit
    atexit.register(time.sleep, 10)
    raise KeyboardInterrupt
    """
    module, name = "terrain", "synthesize_dataset"
    script = _CHILD.format(module=module, name=name, body=textwrap.indent(
        textwrap.dedent(body), "    "))  # fmt: skip
    argv = [sys.executable, "-c", script, "dataset", "synth", "--out", str(tmp_path / "ds")]
    with subprocess.Popen(argv, stderr=subprocess.PIPE, text=True) as child:
        line = ""
        while "STAGE" in line or not line:
            line = child.stderr.readline()
        assert "interrupted" in line
        t0 = time.perf_counter()
        child.send_signal(signal.SIGTERM)
        assert child.wait(timeout=30) == 130  # the first signal's status (SIGINT)
        assert time.perf_counter() - t0 < 5


def test_a_signal_in_the_teardown_after_a_normal_end_exits_143_with_one_line(tmp_path):
    """A SIGTERM in the last moments of a command that ended normally (here held in an exit
    handler that runs after JAX's) ends it with 143 and one line, not by the default action
    (-15)."""
    from whiskerid.fleet import write_table

    fleet = tmp_path / "FLEET"
    fleet.mkdir()
    write_table(fleet / "fleet.csv", [{"whisker": "w0", "session": f"2026-11-2{i}",
                                       "f1_hz": "46.0", "zeta": "0.04", "status": "ok"}
                                      for i in range(4)])  # fmt: skip
    script = textwrap.dedent("""
        import atexit, sys, time
        def teardown():
            print("TEARDOWN", file=sys.stderr, flush=True)
            time.sleep(10)
        atexit.register(teardown)  # registered first: runs last
        from whiskerid.cli._main import main
        sys.argv = ["whiskerid", *sys.argv[1:]]
        sys.exit(main())
    """)
    child, before, came = start_child(script, ["fleet", "check", str(fleet), "--no-plots"],
                                      "TEARDOWN")  # fmt: skip
    assert came, "".join(before)
    t0 = time.perf_counter()
    child.send_signal(signal.SIGTERM)
    err = child.stderr.read()
    assert child.wait(timeout=30) == 143, err
    child.stdout.close()
    child.stderr.close()
    assert time.perf_counter() - t0 < 5
    lines = err.strip().splitlines()
    assert (
        len(lines) == 1
        and "whiskerid fleet check: interrupted (SIGTERM) as it exited" in (lines[0])
    ), err
