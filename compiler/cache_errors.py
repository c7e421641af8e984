"""What to tell a user whose cache folder cannot be written (read-only, full, no permission)."""

from __future__ import annotations

import errno
from pathlib import Path

from sofac.diagnostics import SofacError

_CAUSES = {
    errno.EROFS: "it is on a read-only file system",
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is exhausted",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.ENOTDIR: "a file stands where a folder should be",
    errno.EEXIST: "a file stands where a folder should be",
}


class CacheNotWritable(SofacError):
    """The compile cache could not be written; names the folder, the cause and the fix."""

    def __init__(self, folder: Path, error: OSError) -> None:
        cause = _CAUSES.get(error.errno or 0, error.strerror or str(error))
        where = f" ({error.filename})" if error.filename and str(error.filename) != str(folder) else ""
        super().__init__(
            f"cannot write the compile cache {folder}: {cause}{where}. Free space or fix its permissions, "
            "or set SOFAC_CACHE_DIR to a writable folder (scenes already compiled still load from a "
            "read-only cache)"
        )
        self.folder = folder
        self.errno = error.errno
