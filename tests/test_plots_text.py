"""What a person reads: whole labels, defaults as written, a pluck on its own time scale."""

import numpy as np

from whiskerid.classify import format_confusion
from whiskerid.cli import build_parser
from whiskerid.plot._plot import _activity_end


def test_the_confusion_table_keeps_whole_labels():
    text = format_confusion(np.array([[3, 1], [0, 4]]), ["soft-grass", "carpet"])
    assert "soft-grass" in text.splitlines()[0] and text.splitlines()[1].startswith("soft-grass")


def test_the_address_default_reads_as_an_i2c_address():
    parser = build_parser()
    for command in ("record", "stream"):
        sub = parser._subparsers._group_actions[0].choices[command]
        assert "(default: 0x48)" in " ".join(sub.format_help().split())
        assert sub.get_default("address") == "0x48"
    assert parser.parse_args(["record", "x.csv", "--emulate", "flat"]).address == 0x48


def test_a_pluck_is_shown_over_its_decay_and_a_sine_whole():
    t = np.arange(1000) / 200.0  # 5 s
    pluck = np.exp(-t / 0.08) * np.cos(2 * np.pi * 40 * t)
    end = _activity_end(t, pluck)
    assert end is not None and 0.3 < end < 1.0  # 2 % after 0.31 s, shown to ~0.47 s
    assert _activity_end(t, np.sin(2 * np.pi * 3 * t)) is None
