"""PyBullet, imported without the build-time line its C module prints on stderr at import
(every command of the project would start with it); import it from here."""
import os
import sys


def _import_quietly():
    sys.stderr.flush()
    saved_fd = os.dup(2)
    try:
        null_fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null_fd, 2)
        os.close(null_fd)
        import pybullet
    finally:
        os.dup2(saved_fd, 2)
        os.close(saved_fd)
    return pybullet


pybullet = _import_quietly()
