"""Where a fleet's recordings are: ``ROOT/<whisker-id>/<session>/*.csv|*.npy|*.npz``.

Each whisker folder holds its record, ``whisker.toml`` (or one shared record is given for
all), and one folder per session; a session holds one or more recordings, each with one or
more plucks. Sessions are taken in the order of their names, so names that sort in time
(``2026-11-25``, ``day-007``) give each whisker's history in time order. Names starting with
a dot or an underscore are ignored (temporary and hidden files).
"""

from dataclasses import dataclass
from pathlib import Path

#: Recording formats a session may hold.
RECORDING_SUFFIXES = (".csv", ".npy", ".npz")
#: The record of a whisker, in its folder.
RECORD_NAME = "whisker.toml"

_EXPECTED = (
    "expected ROOT/<whisker-id>/<session>/<recordings>.csv|.npy|.npz, with the whisker's "
    f"record in ROOT/<whisker-id>/{RECORD_NAME} (or one shared record given with --whisker)"
)


class LayoutError(ValueError):
    """A fleet folder that is not laid out as expected (the message says what was found)."""


@dataclass(frozen=True)
class Session:
    """One session of one whisker: its recordings and the record to fit them with.

    Attributes:
        whisker: The whisker's id (its folder's name).
        session: The session's name (its folder's name).
        files: Its recordings, sorted by name.
        record: The whisker record (TOML) the session is fitted with.
        problem: Why the session cannot be fitted (no recordings in it, no record for its
            whisker), or ``""``: such a session gets the status ``bad data`` with this
            reason, and the others go on.
    """

    whisker: str
    session: str
    files: tuple[Path, ...]
    record: Path
    problem: str = ""


def _visible(path: Path) -> bool:
    return not path.name.startswith((".", "_"))


def _listing(folder: Path, limit: int = 5) -> str:
    names = sorted(p.name + ("/" if p.is_dir() else "") for p in folder.iterdir() if _visible(p))
    more = f" and {len(names) - limit} more" if len(names) > limit else ""
    return (", ".join(names[:limit]) + more) if names else "nothing"


def discover(root: str | Path, record: str | Path | None = None) -> list[Session]:
    """The sessions under ``root``, whisker by whisker, sessions in name order.

    Args:
        root: The fleet's recordings, ``ROOT/<whisker-id>/<session>/<recordings>``.
        record: One record shared by every whisker; by default each whisker's own
            ``ROOT/<whisker-id>/whisker.toml``.

    Raises:
        LayoutError: ``root`` is not a folder, holds no whisker folders, a whisker has no
            sessions, or recordings lie outside session folders. The message says what was
            found and what is expected. A whisker without its record, or a session without
            recordings, is not an error of the whole fleet: its sessions carry the
            :attr:`Session.problem`.
    """
    root = Path(root)
    if not root.is_dir():
        what = "does not exist" if not root.exists() else "is a file"
        raise LayoutError(f"{root} {what}; {_EXPECTED}")
    shared = None if record is None else Path(record)
    if shared is not None and not shared.is_file():
        raise LayoutError(f"the shared record {shared} is not a file")
    whiskers = sorted(p for p in root.iterdir() if p.is_dir() and _visible(p))
    stray = sorted(p.name for p in root.iterdir() if p.is_file() and _visible(p)
                   and p.suffix.lower() in RECORDING_SUFFIXES)  # fmt: skip
    if stray:
        raise LayoutError(f"{root} holds recordings ({', '.join(stray[:3])}) directly; {_EXPECTED}")
    if not whiskers:
        raise LayoutError(f"{root} holds no whisker folders (found {_listing(root)}); {_EXPECTED}")
    out = []
    for w in whiskers:
        own = w / RECORD_NAME
        rec = shared if shared is not None else own
        no_record = ""
        if not rec.is_file():
            no_record = (
                f"whisker {w.name}: no record {own} (found {_listing(w)}); put the "
                "whisker's record there or give one shared record with --whisker"
            )
        stray = sorted(p.name for p in w.iterdir() if p.is_file() and _visible(p)
                       and p.suffix.lower() in RECORDING_SUFFIXES)  # fmt: skip
        if stray:
            raise LayoutError(
                f"whisker {w.name}: recordings ({', '.join(stray[:3])}) lie directly in {w}, "
                f"not in a session folder; {_EXPECTED}"
            )
        sessions = sorted(p for p in w.iterdir() if p.is_dir() and _visible(p))
        if not sessions:
            raise LayoutError(f"whisker {w.name}: no session folders in {w}; {_EXPECTED}")
        for s in sessions:
            files = tuple(sorted(p for p in s.iterdir() if p.is_file() and _visible(p)
                                 and p.suffix.lower() in RECORDING_SUFFIXES))  # fmt: skip
            problem = no_record
            if not files:
                problem = (f"session {w.name}/{s.name} holds no recordings (found "
                           f"{_listing(s)}); {_EXPECTED}")  # fmt: skip
            out.append(Session(w.name, s.name, files, rec, problem))
    return out
