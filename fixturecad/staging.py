"""Output folders written whole or not at all, replacing only what fixturecad wrote.

Every command that writes a folder (``build``, ``calibrate``, ``design``)
fills a temporary folder ``.<name>.<pid>.tmp`` beside the target and moves it
into place when complete; one that adds files to a folder (``plan``,
``simulate``) writes them into such a folder inside it and moves them in
together (:func:`staged_files`). An interrupted command (Ctrl-C,
SIGTERM) removes its temporary folder and exits with 130 or 143; one left by
a killed process (its pid no longer running) is removed by the next command
writing beside it. An
existing target is replaced only with ``force``, and only if it is a folder
fixturecad wrote (it holds a fixturecad features.json) or an empty folder;
never a command's own input folder, nor a drawing by an as-built folder or
the reverse. Each folder lists what fixturecad wrote in it (:data:`MANIFEST`):
``force`` replaces those files and keeps every other one (a user's touch
files, ``plans/``, ``simulation.*``), hard-linked into the new folder before
it is moved in, so that an interruption loses nothing.
"""

import json
import os
import shutil
import tempfile
from contextlib import ExitStack, contextmanager
from pathlib import Path

from fixturecad.errors import InputError, write_error
from fixturecad.interrupt import held, removing

FEATURES_SCHEMA_PREFIX = "fixturecad.features/"  # any version: a folder from an older fixturecad is still ours
MANIFEST = "fixturecad-files.json"  # {"files": [...]}: the files fixturecad wrote in a folder, relative paths
KINDS = {"drawing": "a drawing (fixturecad build or design)", "as-built": "an as-built folder (fixturecad calibrate)"}


def written_by_fixturecad(folder: Path) -> bool:
    """Whether ``folder`` holds a features.json that fixturecad wrote."""
    try:
        document = json.loads((Path(folder) / "features.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(document, dict) and str(document.get("schema", "")).startswith(FEATURES_SCHEMA_PREFIX)


def folder_kind(folder: Path) -> str:
    """``drawing`` or ``as-built``: what a folder fixturecad wrote holds (its features.json has a calibration)."""
    try:
        document = json.loads((Path(folder) / "features.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return "drawing"
    return "as-built" if isinstance(document, dict) and "calibration" in document else "drawing"


def written_files(folder: Path):
    """The files (relative paths) fixturecad wrote in ``folder`` by its manifest; None without one."""
    try:
        manifest = json.loads((Path(folder) / MANIFEST).read_text(encoding="utf-8"))
        return {str(name) for name in manifest["files"]}
    except (OSError, ValueError, RecursionError, KeyError, TypeError):
        return None


def check_target(target: Path, force: bool, kind: str = "drawing", inputs=()) -> Path:
    """The target folder if it may be written with a folder of ``kind`` by a command that reads the folders
    ``inputs``; InputError (one line) naming the reason if not."""
    if str(target) in ("", "."):
        raise InputError("the output folder must be a new folder, not the current one")
    target = Path(target)
    resolved = target.resolve()
    if resolved == Path.cwd() or resolved in Path.cwd().parents or resolved == resolved.parent:
        raise InputError(f"{target} holds the current folder: choose a new output folder")
    existing = _nearest_existing(resolved.parent)
    if not existing.is_dir():
        raise InputError(f"{existing} is a file, not a folder: cannot write {target}")
    for folder in inputs:
        if resolved == Path(folder).resolve() or resolved in Path(folder).resolve().parents:
            raise InputError(f"{target} is or holds {folder}, the folder this command reads: choose another output folder")
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        raise InputError(f"{target} exists and is not a folder; fixturecad replaces only folders it wrote")
    if target.is_dir() and any(target.iterdir()):
        if not force:
            raise InputError(f"{target} already exists; pass --force to replace it")
        if not written_by_fixturecad(target):
            raise InputError(f"{target} was not written by fixturecad (no fixturecad features.json): not replaced")
        if folder_kind(target) != kind:
            raise InputError(f"{target} is {KINDS[folder_kind(target)]}: not replaced by {KINDS[kind]}; "
                             "choose another output folder")
    return target


@contextmanager
def staged_folder(target: Path, force: bool = False, kind: str = "drawing", inputs=()):
    """Yield an empty temporary folder beside ``target``; move it into place when the block completes, with
    its manifest and the files of the target fixturecad did not write.

    On any error or interruption the temporary folder is removed and the
    target is left as it was. OSErrors become one-line errors: an InputError
    (a read-only or missing parent), an EnvironmentFault (a full disk).
    See :func:`check_target` for ``kind`` and ``inputs``.
    """
    target = check_target(target, force, kind, inputs)
    with ExitStack() as stack:
        staging = _staging(stack, target.parent, target.name)
        staging.chmod(0o777 & ~_umask())  # mkdtemp makes it private; the result is an ordinary folder
        try:
            yield staging
            _write_manifest(staging)
            if target.exists():
                _keep_theirs(target, staging)
            _move_into_place(staging, target)
        except OSError as error:
            shutil.rmtree(staging, ignore_errors=True)
            raise write_error(error, target) from None
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise


def check_files(folder: Path, names, force: bool) -> Path:
    """A folder to write the named files into; InputError if one exists and not ``force``. A missing folder is
    made only when the files are moved in (:func:`staged_files`): an interrupted command leaves none."""
    folder = Path(folder)
    existing = [name for name in names if (folder / name).exists()]
    if existing and not force:
        raise InputError(f"{folder / existing[0]} already exists; pass --force to replace it")
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder} is a file, not a folder")
    parent = _nearest_existing(folder)
    if not parent.is_dir():
        raise InputError(f"{parent} is a file, not a folder: cannot write {folder}")
    try:
        tempfile.TemporaryFile(dir=parent).close()  # a folder it cannot write in is refused before the work
    except OSError as error:
        raise write_error(error, f"in {parent}") from None
    return folder


@contextmanager
def staged_files(folder: Path, names):
    """Yield an empty temporary folder to write the files ``names`` into; moved into ``folder`` (made if
    missing) together when the block completes. On any error or interruption nothing is left: no file, no
    folder."""
    folder = Path(folder)
    parent = _nearest_existing(folder)
    with ExitStack() as stack:
        staging = _staging(stack, parent, folder.name)
        try:
            yield staging
            folder.mkdir(parents=True, exist_ok=True)
            for name in names:
                os.replace(staging / name, folder / name)
        except OSError as error:
            raise write_error(error, folder) from None
        finally:
            shutil.rmtree(staging, ignore_errors=True)


def _staging(stack: ExitStack, parent: Path, name: str) -> Path:
    """A new temporary folder ``.<name>.<pid>.*.tmp`` in ``parent`` (made if missing), the stale ones of processes
    that no longer run cleared first; made and registered for removal on an interrupt as one step (an interrupt
    between the two would leave it), the registration held by ``stack``."""
    with held():
        try:
            parent.mkdir(parents=True, exist_ok=True)
            _remove_stale(parent, name)
            staging = Path(tempfile.mkdtemp(prefix=f".{name}.{os.getpid()}.", suffix=".tmp", dir=parent))
        except OSError as error:
            raise write_error(error, f"in {parent}") from None
        stack.enter_context(removing(staging))
    return staging


def _nearest_existing(path: Path) -> Path:
    """``path`` if it exists, else its nearest ancestor that does (where a missing folder would be made)."""
    return next(folder for folder in (path, *path.resolve().parents) if folder.exists())


def _remove_stale(where: Path, name: str) -> None:
    """Remove the temporary folders for ``name`` in ``where`` left by processes that no longer run."""
    for path in [*where.glob(f".{name}.*.tmp"), *where.glob(f".{name}.*.old")]:
        parts = path.name[len(name) + 2:].split(".")
        if parts[0].isdigit() and not _running(int(parts[0])):
            shutil.rmtree(path, ignore_errors=True)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _files(folder: Path) -> set:
    return {str(path.relative_to(folder)) for path in folder.rglob("*") if path.is_file() or path.is_symlink()}


def _write_manifest(staging: Path) -> None:
    files = sorted(_files(staging))
    (staging / MANIFEST).write_text(json.dumps({"files": files}, indent=1) + "\n", encoding="utf-8")


def _keep_theirs(target: Path, staging: Path) -> None:
    """Link the target's files fixturecad did not write into ``staging`` (a folder without a manifest: every
    file but those written anew). InputError if one of them has the name of a new file."""
    new = _files(staging)
    ours = written_files(target)
    theirs = _files(target) - (new if ours is None else ours) - {MANIFEST}
    clash = sorted(theirs & new)
    if clash:
        raise InputError(f"{target / clash[0]} is not a file fixturecad wrote but has the name of one: "
                         "move it away to replace the folder")
    for name in sorted(theirs):
        (staging / name).parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(target / name, staging / name, follow_symlinks=False)
        except OSError:  # a file system without hard links
            shutil.copy2(target / name, staging / name, follow_symlinks=False)


def _move_into_place(staging: Path, target: Path) -> None:
    if target.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{target.name}.{os.getpid()}.", suffix=".old", dir=target.parent))
        # An interrupt between the two renames would leave no target and the old one (with the user's own files)
        # in a folder the next command clears as stale: it waits until the new one is in place.
        with held():
            os.replace(target, old / target.name)
            os.replace(staging, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(staging, target)
