"""pyvista, imported lazily (the optional `viz` extra), with offscreen EGL where there is no display."""

from __future__ import annotations

import os
import sys


class VizUnavailable(RuntimeError):
    """pyvista (or an OpenGL context) is not available here; the message says what to install."""


def has_display() -> bool:
    """True where a window can open: macOS/Windows, or an X / Wayland display on Linux."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def import_pyvista():
    """Import pyvista, choosing EGL for offscreen rendering where there is no display (TECH-NOTES: the X
    attempt costs ~2 s otherwise). Raises VizUnavailable with the install line if it is missing."""
    if not has_display() and sys.platform.startswith("linux"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista as pv
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise VizUnavailable(
            f"rendering needs the viz extra: pip install 'piezotwin[viz]' ({exc})"
        ) from None
    return pv
