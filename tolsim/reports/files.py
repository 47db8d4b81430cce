"""Writing a report's files all or nothing: each through a temporary file and a rename, and
on an error (a full disk, say) what was written is removed, so no file is left half-written.
"""

import os

__all__ = ["check_folder", "write_files"]


def check_folder(folder) -> None:
    """Raise ValueError naming ``folder`` if it exists and is not a folder: called before a
    report's work, so a wrong output path fails at once, not after the figures."""
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise ValueError(f"{os.fspath(folder)} exists and is not a folder: give the report a "
                         "folder")


def write_files(folder, files: dict) -> dict:
    """Write {name: bytes} into ``folder`` (created if missing), each through a temporary
    file and a rename; on an error, remove what was written (and the folder if made here)."""
    check_folder(folder)
    created = not os.path.isdir(folder)
    os.makedirs(folder, exist_ok=True)
    written = {}
    try:
        for name, data in files.items():
            path = os.path.join(folder, name)
            tmp = f"{path}.tmp"
            with open(tmp, "wb") as fh:
                fh.write(data)
            os.replace(tmp, path)
            written[name] = path
    except BaseException:
        for path in [*written.values(), *(os.path.join(folder, f"{n}.tmp") for n in files)]:
            if os.path.exists(path):
                os.unlink(path)
        if created and not os.listdir(folder):
            os.rmdir(folder)
        raise
    return written
