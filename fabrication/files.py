"""Atomic file output: a file appears complete under its final name, or not at all.

Every writer in gridshell goes through ``atomic_path``: it yields a temporary path in
the same folder, and renames it onto the target only when the block ends without error.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path", "atomic_folder", "write_text_atomic", "write_bytes_atomic", "save_dxf"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success rename it onto ``target``.

    The temporary name keeps the target's suffix (some writers choose the format by it).
    On an exception the temporary file is removed and the target is left untouched.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=suffix or target.suffix,
                                    dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    os.chmod(tmp, 0o666 & ~_umask())
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(target: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``target`` atomically; returns the target path."""
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(target)


def write_bytes_atomic(target: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``target`` atomically; returns the target path."""
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)
    return Path(target)


def atomic_folder(parent: str | os.PathLike, name: str) -> Path:
    """A new empty temporary folder in ``parent`` (mode as for an ordinary new folder).

    The caller fills it and renames it onto its final name when complete.
    """
    path = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=parent))
    os.chmod(path, 0o777 & ~_umask())
    return path


def save_dxf(doc, target: str | os.PathLike) -> Path:
    """Save an ezdxf document atomically with fixed metadata and a sorted CLASSES section: ezdxf
    stamps the time and fresh GUIDs ($TDUPDATE, $VERSIONGUID, ...) into every file it writes, and
    orders its classes as a set (by the process's hash seed), so the same drawing gave different
    bytes on every run; here the same drawing gives the same file."""
    from collections import OrderedDict

    import ezdxf

    doc.classes.add_required_classes(doc.dxfversion)
    doc.classes.classes = OrderedDict(sorted(doc.classes.classes.items()))
    doc.ezdxf_metadata()["CREATED_BY_EZDXF"] = f"ezdxf {ezdxf.__version__}"  # stamped with the time at ezdxf.new
    before = ezdxf.options.write_fixed_meta_data_for_testing
    ezdxf.options.write_fixed_meta_data_for_testing = True
    try:
        with atomic_path(target) as tmp:
            doc.saveas(tmp)
    finally:
        ezdxf.options.write_fixed_meta_data_for_testing = before
    return Path(target)
