"""Safe output files: every output path checked before any computing, writes atomic.

The command line and the experiment runner plan their outputs first
(:func:`check_output`, :func:`check_folder`): a path that cannot be written, that
is one of the inputs or that leaves the folder it must stay in is a ValueError
naming it before any work is done.  Each file is then written to a temporary file
in its own folder and renamed over the target (:func:`atomic_path`): a crash, a
full disk or an interrupt leaves the old file or none, never half of one.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

__all__ = ["absolute", "atomic_folder", "atomic_path", "check_folder", "check_output", "safe_name", "write_text"]


def absolute(path) -> Path:
    """``path`` made absolute with its symbolic links resolved (where they exist)."""
    return Path(os.path.expanduser(os.fspath(path))).resolve()


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _nearest_existing(p: Path) -> Path:
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_folder(folder, what: str = "output") -> Path:
    """Check that files can be written in ``folder``: it is a writable folder, or it
    can be created (its nearest existing ancestor is a writable folder).  Nothing is
    created.  Returns it absolute; ValueError naming ``what`` otherwise."""
    d = absolute(folder)
    anc = _nearest_existing(d)
    if not anc.is_dir():
        where = "is a file" if anc == d else f"cannot be created: {anc} is a file, not a folder"
        raise ValueError(f"{what}: the folder {d} {where}; choose another place")
    try:  # the truth, not os.access: read-only mounts, ACLs, a super-user's rights
        fd, probe = tempfile.mkstemp(dir=anc, prefix=".sorjax-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise ValueError(f"{what}: cannot write in {anc} ({e.strerror or e}); choose a writable place") from None
    return d


def _same_file(a: Path, b: Path) -> bool:
    if a == b:
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)  # hard links
    except OSError:
        return False


def check_output(path, *, inputs=(), inside=None, what: str = "output") -> Path:
    """Check before any work that the file ``path`` can be written: it is not a
    folder, its folder exists or can be created and is writable, it is none of
    ``inputs`` (paths; compared after resolving links) and, when ``inside`` is given,
    it lies inside that folder.  Returns it absolute; ValueError naming ``what``
    (e.g. the command-line flag) otherwise."""
    p = absolute(path)
    if p.is_dir():
        raise ValueError(f"{what}: {path} is a folder; give a file name")
    if inside is not None and not p.is_relative_to(absolute(inside)):
        raise ValueError(f"{what}: {path} would be written outside {inside}")
    for q in inputs:
        if _same_file(p, absolute(q)):
            raise ValueError(f"{what}: writing {p.name} would replace the input {q}; choose another output name")
    check_folder(p.parent, what)
    return p


def safe_name(name: str, default: str = "run") -> str:
    """``name`` as one plain file or folder name: every character other than a letter,
    a digit, ``.``, ``_`` or ``-`` replaced by ``_``, then leading dots and
    underscores dropped (no ``..``, no hidden name: ``"../../x"`` gives ``"x"``);
    ``default`` when nothing is left."""
    s = re.sub(r"[^A-Za-z0-9._-]", "_", str(name)).lstrip("._")
    return s if s.strip("_") else default


@contextmanager
def atomic_path(path):
    """Write ``path`` atomically: yields a temporary path in the same folder with the
    same suffix (so writers that pick the format by the suffix, e.g. OpenCV, work);
    when the block ends without error the temporary file replaces ``path``
    (``os.replace``), otherwise it is removed.  The folder is created if needed."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.stem}.", suffix=f".tmp{p.suffix}")
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's file is private; outputs get the usual mode
        os.replace(tmp, p)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_text(path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


@contextmanager
def atomic_folder(path):
    """Create the folder ``path`` atomically: yields a temporary folder beside it to
    fill; when the block ends without error it is renamed to ``path`` (which must not
    exist), otherwise it is deleted with its contents."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp"))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())
        os.rename(tmp, p)  # fails if p exists and is not an empty folder
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
