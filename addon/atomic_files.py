"""Every file the add-on writes is written whole or not at all (issue 67; no bpy).

A file is written to PATH.partial and renamed over PATH only once it is complete and closed, so a
full disk, a failed write or an exception while writing leaves the previous file as it was,
never half of a new one standing in for a result.
"""

import contextlib
import os


class WriteError(OSError):
    """A file that could not be written: one line naming it (not its .partial) and why. An OSError,
    so every handler that reports OSErrors reports it."""

    def __str__(self):
        return "cannot write %s: %s" % (self.filename, self.strerror)


@contextlib.contextmanager
def written_atomically(path):
    """A text file whose content replaces PATH when the block ends without an exception. On any
    exception PATH is untouched and the partial file removed; an OSError comes out as WriteError."""
    partial = path + ".partial"
    opened = False
    try:
        with open(partial, "w", encoding="utf-8") as fh:
            opened = True
            yield fh
        os.replace(partial, path)
    except BaseException as exc:
        if opened:  # what stood at PATH.partial before a failed open is not ours to remove
            with contextlib.suppress(OSError):
                os.remove(partial)
        if isinstance(exc, OSError):
            raise WriteError(exc.errno, exc.strerror or str(exc), path) from exc
        raise
