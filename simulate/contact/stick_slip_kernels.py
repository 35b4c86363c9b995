"""Warp kernels of the Coulomb stick-slip shear of the "press_stroke" contact stage: the same law as
`simulate.contact.press_stroke.stick_slip` (its numpy reference, tested equal).

Model (Johnson, Contact Mechanics, 1985, sect. 7.2, the Cattaneo-Mindlin stick-slip limit): f = k_t (x - a),
and where |f| > mu N the force is held on the friction cone and the stick anchor a dragged behind; out of contact
(N = 0) the anchor follows the indenter. State in float64, like the reference.

- `stick_slip_update`: one physics step of one indenter (shared by both stages' kernels);
- `_stick_slip_path`: a whole path, one thread per (episode, indenter) walking its steps: the C MuJoCo path, which
  records the path first (`mujoco.rollout`) and applies the law after (the shear does not act back on MuJoCo);
- the MuJoCo Warp path applies `stick_slip_update` after every device step (`simulate.contact.mujoco_warp`).
"""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.func
def stick_slip_update(x: wp.float64, y: wp.float64, cap: wp.float64, ax: wp.float64, ay: wp.float64,
                      k_t: wp.float64):
    """One step: (f_x, f_y, a_x, a_y) from the indenter at (x, y), the friction cap mu N (N) and the anchor."""
    if not (cap > wp.float64(0.0)):  # out of contact: the anchor follows the indenter
        ax = x
        ay = y
    fx = k_t * (x - ax)
    fy = k_t * (y - ay)
    mag = wp.sqrt(fx * fx + fy * fy)
    if mag > cap:  # slip: the force on the friction cone, the anchor dragged behind
        sc = cap / mag
        fx = fx * sc
        fy = fy * sc
        ax = x - fx / k_t
        ay = y - fy / k_t
    return wp.vec4d(fx, fy, ax, ay)


@wp.kernel
def _stick_slip_path(xy: wp.array4d(dtype=wp.float64), normal: wp.array3d(dtype=wp.float64), k_t: wp.float64,
                     mu: wp.float64, out: wp.array4d(dtype=wp.float64)):
    e, c = wp.tid()
    ax = xy[e, 0, c, 0]
    ay = xy[e, 0, c, 1]
    for s in range(xy.shape[1]):
        r = stick_slip_update(xy[e, s, c, 0], xy[e, s, c, 1], mu * normal[e, s, c], ax, ay, k_t)
        out[e, s, c, 0] = r[0]
        out[e, s, c, 1] = r[1]
        ax = r[2]
        ay = r[3]


def stick_slip_path(xy: np.ndarray, normal_n: np.ndarray, k_t: float, mu: float, device: str = "cpu") -> np.ndarray:
    """`simulate.contact.press_stroke.stick_slip` by the Warp kernel. xy: (E, S, C, 2) indenter x/y (m) at physics
    steps; normal_n: (E, S, C) normal force (N, >= 0). Returns the (E, S, C, 2) tangential force on the pad (N)."""
    from sensors.warp_setup import init_warp

    init_warp()
    E, S, C, _ = xy.shape
    with wp.ScopedDevice(device):
        out = wp.empty((E, S, C, 2), dtype=wp.float64)
        wp.launch(_stick_slip_path, dim=(E, C), inputs=[wp.array(np.ascontiguousarray(xy, np.float64), dtype=wp.float64),
                                                       wp.array(np.ascontiguousarray(normal_n, np.float64), dtype=wp.float64),
                                                       wp.float64(k_t), wp.float64(mu), out])
        return out.numpy()
