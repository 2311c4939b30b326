"""Off-screen renders without a display: EGL directly, nothing printed on the standard error."""

from __future__ import annotations

import os
import subprocess
import sys

SCRIPT = """
import pyvista as pv
from reports.render import off_screen_plotter
p = off_screen_plotter(window_size=[120, 100])
p.set_background("white")
p.add_mesh(pv.Sphere(), color="red")
img = p.screenshot(return_img=True)
p.close()
print(type(p.ren_win).__name__ if p.ren_win is not None else "closed", int((img[..., 1] < 128).sum()))
"""


def test_off_screen_plotter_renders_on_egl_without_a_warning():
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "VTK_DEFAULT_OPENGL_WINDOW")}
    out = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "X server" not in out.stderr and "WARN" not in out.stderr, out.stderr
    window, red = out.stdout.split()[-2:]
    assert int(red) > 500  # the sphere was drawn: red pixels (green channel low) on white
