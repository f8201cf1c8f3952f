"""Outputs that never destroy what the user did not ask to replace.

Rules, for every file and directory selfalign writes:

* **Atomic.** A file is written under a temporary name beside its target and renamed
  into place only when complete (:func:`atomic_output`); a directory is filled as a
  temporary sibling and renamed into place (:func:`output_directory`). A failure, Ctrl-C
  or SIGTERM (the CLI turns it into an exception) removes the temporary.
* **Checked before any work** (:func:`check_output_file`, :func:`check_output_dir`):
  an output is never an input file, a symbolic link, a device node, a FIFO or a
  directory (for a file); an output directory is never ``.``, ``..`` (or any directory
  holding the working directory), an input's directory or one above it, a symbolic
  link, or read-only.
* **Files are replaced only when asked.** An output file the user names that exists
  already is refused before any work (:func:`require_new_file`) unless ``--force`` is
  given; an input of the run is never replaced, even with ``--force``.
* **Directories are replaced only when asked and only when ours.** An existing empty
  directory is filled; a non-empty one is refused, or with ``force=True`` replaced only
  if it holds nothing but a previous selfalign output: its marker file
  :data:`MARKER` lists every file selfalign wrote there.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from foundation._errors import InputError
from foundation._hold import hold

#: Marker file of an output directory: JSON listing the files selfalign wrote there.
MARKER = ".selfalign-output.json"

#: Temporaries that exist right now (files and directories), for :func:`remove_pending`.
_PENDING: set[Path] = set()


def json_text(obj, indent: int | None = 2, default=None) -> str:
    """The text of a result file in JSON, the one format of every JSON file selfalign writes:
    ``indent`` spaces (None: one line, a journal's row), no NaN or infinity (ValueError: a
    result's numbers are finite), and a final newline. ``default``: as :func:`json.dumps`."""
    return json.dumps(obj, indent=indent, allow_nan=False, default=default) + "\n"


def remove_pending() -> None:
    """Remove every temporary output that exists now: for a signal handler that must end
    the process at once (SIGTERM), where unwinding through ``finally`` could deadlock."""
    for p in list(_PENDING):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                p.unlink()
        _PENDING.discard(p)


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def _resolved(paths: Iterable[str | os.PathLike | None]) -> list[Path]:
    return [Path(p).resolve() for p in paths if p]


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def check_output_file(
    path: str | os.PathLike, flag: str, inputs: Iterable[str | os.PathLike | None] = ()
) -> Path:
    """Refuse, before any work, an output file that cannot or must not be written.

    ``flag`` names the option in the message (``--json``); ``inputs`` are the files the
    run reads (pattern, chip, scene), which an output may never replace.
    """
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise InputError(f"{flag} {str(path)!r}: give a file name")
    try:
        st = os.lstat(p)
    except (FileNotFoundError, NotADirectoryError):
        st = None
    except OSError as err:
        raise InputError(
            f"{flag} {path}: cannot be checked ({err.strerror or err}); choose another path"
        ) from None
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            raise InputError(
                f"{flag} {path}: is a symbolic link; give the path of a regular file (the link is not replaced)"
            )
        if stat.S_ISDIR(st.st_mode):
            raise InputError(f"{flag} {path} is a directory; give a file name")
        if not stat.S_ISREG(st.st_mode):
            raise InputError(
                f"{flag} {path}: is a device, FIFO or socket, not a regular file; give a file name"
            )
        for inp in _resolved(inputs):
            if _same_file(p, inp):
                raise InputError(
                    f"{flag} {path}: is an input of this run; choose another file name (inputs are never overwritten)"
                )
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(
            f"{flag} {path}: directory {parent} does not exist; create it or choose another path"
        )
    if not os.access(parent, os.W_OK):
        raise InputError(f"{flag} {path}: directory {parent} is not writable; choose another path")
    probe_writable(parent, f"{flag} {path}")
    return p


def require_new_file(path: str | os.PathLike, flag: str, force: bool = False) -> None:
    """Refuse, before any work, an output file that exists unless ``force`` (``--force``) is
    given: a command replaces only the files it is asked to replace. Checked with ``lstat``,
    so a dangling link counts as existing too (:func:`check_output_file` refuses links)."""
    if force:
        return
    try:
        os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return
    except OSError:
        return  # check_output_file says why it cannot be checked
    raise InputError(
        f"{flag} {path}: exists; choose a new file name, or pass --force to replace it"
    )


def probe_writable(directory: Path, what: str, kind: str = "file") -> None:
    """InputError unless a file (``kind="dir"``: a directory) can really be made in ``directory``.

    ``os.access`` answers yes for root on a read-only mount, /proc or /sys, where creating
    the temporary fails later (after the work): so one is made and removed here, before any.
    """
    try:
        if kind == "dir":
            os.rmdir(tempfile.mkdtemp(prefix=".selfalign-probe.", dir=directory))
        else:
            fd, name = tempfile.mkstemp(prefix=".selfalign-probe.", dir=directory)
            os.close(fd)
            os.unlink(name)
    except OSError as err:
        why = (
            "a file system that takes no new files"
            if err.errno == errno.ENOENT
            else (err.strerror or str(err))
        )
        raise InputError(
            f"{what}: cannot write in directory {directory} ({why}); choose another path"
        ) from None


def check_distinct(outputs: dict[str, str | os.PathLike | None]) -> None:
    """Refuse two output flags that name the same file (``{"--json": path, ...}``)."""
    seen: dict[Path, str] = {}
    for flag, path in outputs.items():
        if not path:
            continue
        r = Path(path).resolve()
        if r in seen:
            raise InputError(f"{flag} and {seen[r]} name the same file {path}")
        seen[r] = flag


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; move it into place only on success.

    A failure anywhere inside the block (an exception, Ctrl-C, SIGTERM through the CLI's
    handler, a full disk) leaves no file at ``path`` and no temporary. The parent
    directory must exist and be writable, and ``path`` must not be a symbolic link, a
    device or a directory, else InputError.
    """
    path = check_output_file(path, "output")
    parent = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=parent)
    os.close(fd)
    tmp_path = Path(tmp)
    _PENDING.add(tmp_path)
    try:
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes files owner-only
        os.replace(tmp_path, path)
    except OSError as err:
        raise _attributed(err, path) from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        _PENDING.discard(tmp_path)


def _attributed(err: OSError, target: Path) -> OSError:
    """``err`` naming the output it failed on (a failed write() names no file)."""
    if (
        err.filename is None
        or ".selfalign-tmp" in str(err.filename)
        or Path(str(err.filename)).name.startswith(".")
    ):
        return type(err)(err.errno, err.strerror or str(err), str(target))
    return err


# --------------------------------------------------------------------- directories
def _writable_dir(path: Path) -> bool:
    """Writable by this process, read-only mode bits honoured even for root."""
    mode = os.stat(path).st_mode
    return os.access(path, os.W_OK) and bool(mode & stat.S_IWUSR)


def tree_listing(root: Path) -> list[str]:
    """Every entry below ``root`` as a relative POSIX path (directories end in '/')."""
    out = []
    for dirpath, dirnames, filenames in os.walk(root):
        rel = Path(dirpath).relative_to(root)
        out += [(rel / d).as_posix() + "/" for d in dirnames]
        out += [(rel / f).as_posix() for f in filenames]
    return sorted(out)


def _previous_output(out: Path) -> bool:
    """True if ``out`` holds exactly the files its selfalign marker lists (and the marker)."""
    try:
        doc = json.loads((out / MARKER).read_text())
        listed = set(doc["files"]) | {MARKER}
    except (OSError, ValueError, KeyError, TypeError):
        return False
    for entry in tree_listing(out):
        if entry.endswith("/"):
            if not any(f.startswith(entry) for f in listed):
                return False
        elif entry not in listed:
            return False
    return not any(
        os.path.islink(os.path.join(dp, n)) for dp, dn, fn in os.walk(out) for n in dn + fn
    )


def check_output_dir(
    path: str | os.PathLike,
    flag: str = "--out",
    force: bool = False,
    inputs: Iterable[str | os.PathLike | None] = (),
) -> Path:
    """Refuse, before any work, an output directory that must not be written or replaced."""
    out = Path(path)
    if str(path) == "":
        raise InputError(f"{flag}: give a directory name")
    if out.is_symlink():
        raise InputError(
            f"{flag} {path}: is a symbolic link; give the real directory (links are never replaced)"
        )
    r = out.resolve()
    cwd = Path.cwd().resolve()
    if r == cwd or r in cwd.parents:
        raise InputError(
            f"{flag} {path}: is the working directory or holds it; give a new directory name, e.g. {flag} out"
        )
    for inp in _resolved(inputs):
        if r == inp or r in inp.parents:
            raise InputError(
                f"{flag} {path}: holds an input of this run ({inp.name}); give a new directory name"
            )
    if out.exists() and not out.is_dir():
        raise InputError(f"{flag} {path}: exists and is not a directory; choose a directory name")
    parent = r.parent
    if not parent.is_dir():
        raise InputError(
            f"{flag} {path}: parent directory {out.parent} does not exist; create it first"
        )
    if not os.access(parent, os.W_OK):
        raise InputError(f"{flag} {path}: parent directory {out.parent} is not writable")
    probe_writable(parent, f"{flag} {path}", "dir")
    if out.is_dir():
        if not _writable_dir(out):
            raise InputError(
                f"{flag} {path}: directory is read-only; make it writable or choose another"
            )
        if any(out.iterdir()):
            if not force:
                raise InputError(
                    f"{flag} {path}: directory exists and is not empty; choose a new directory, or pass --force "
                    "to replace a previous selfalign output"
                )
            if not _previous_output(out):
                raise InputError(
                    f"{flag} {path}: holds files selfalign did not write; not replaced even with --force (choose another directory)"
                )
    return out


@contextlib.contextmanager
def output_directory(
    path: str | os.PathLike,
    flag: str = "--out",
    force: bool = False,
    inputs: Iterable[str | os.PathLike | None] = (),
    command: str = "",
) -> Iterator[Path]:
    """Yield a temporary directory beside ``path``; it becomes ``path`` only on success.

    On success a marker file listing what was written is added, and the directory is
    renamed into place: onto a missing or empty ``path`` (keeping an empty directory's
    mode), or, with ``force``, in place of a previous selfalign output (checked again).
    On any failure the temporary is removed and ``path`` is untouched.
    """
    out = check_output_dir(path, flag, force, inputs)
    parent = out.resolve().parent
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".selfalign-tmp", dir=parent))
    _PENDING.add(tmp)
    old: Path | None = None
    try:
        hold("output")
        yield tmp
        files = [e for e in tree_listing(tmp) if not e.endswith("/")]
        (tmp / MARKER).write_text(
            json.dumps({"tool": "selfalign", "command": command, "files": files}, indent=1) + "\n"
        )
        check_output_dir(out, flag, force, inputs)  # nothing changed meanwhile
        if out.is_dir():
            mode = stat.S_IMODE(os.stat(out).st_mode)
            if any(out.iterdir()):  # a previous selfalign output, replaced as asked
                old = Path(
                    tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".selfalign-old", dir=parent)
                )
                os.replace(out, old / "d")
                _PENDING.add(old)
            os.replace(tmp, out)
            os.chmod(out, mode)
        else:
            os.rename(tmp, out)
            os.chmod(out, 0o777 & ~_umask())
    except OSError as err:
        if old is not None and (old / "d").exists() and not out.exists():
            os.replace(old / "d", out)  # put the previous output back
        if (
            isinstance(err, FileExistsError | IsADirectoryError)
            or getattr(err, "errno", None) == 39
        ):
            raise InputError(
                f"{flag} {path}: was created by someone else while this ran; nothing replaced"
            ) from None
        raise _attributed(err, out) from None
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        _PENDING.discard(tmp)
        if old is not None:
            _PENDING.discard(old)
