"""Scene config -> MJCF: a static pad, a jointed rigid indenter, x/y/z actuators, contact sensors.

Geometry (world frame, SI): the pad is a box geom with its bottom at z = 0 and its top at
z = pad.thickness_m, centred at x = y = 0. The indenter body origin sits at the pad top (x = y = 0);
its geom is placed so that the indenter's lowest point is at the body origin. Three slide joints
(x, y, z) move it, so `qpos = (x, y, z)` with z = height of the indenter's lowest point above the
undeformed pad top: penetration = -qpos[2].

Contact model (Winkler foundation; Johnson, Contact Mechanics, 1985, sect. 5.8): the pad under the
indenter acts as a spring k = E * A_contact / thickness. MuJoCo's soft contact with a direct
(negative) solref = (-s, -b) and impedance d (solimp dmin = dmax = d) has, in steady state, a normal
stiffness per contact point of

    k_point = s / ((1 - d) * w)      w = body_invweight0 (translational inverse weight of the indenter)

(measured in this build within 0.3 %), and box-on-box face contact yields 4 contact points (sphere-box: 1).
So s = k * (1 - d) * w / n_points. See `contact_design`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from scenes.config import SceneConfig

INDENTER_BOX_THICKNESS_M = 0.005  # estimate: only its bottom face matters
CONTACT_IMPEDANCE = 0.01  # estimate: solimp dmin = dmax; small d makes the contact a penalty spring (see below)
CONTACT_DAMPING_RATIO = 0.01  # estimate: light (the z servo or joint damping damps the motion); pad viscoelasticity is modelled downstream (sensors), not here
SERVO_STIFFNESS_RATIO = 100.0  # estimate: position-servo kp / pad stiffness -> ~1 % static tracking error
SERVO_OMEGA_DT = 0.3  # estimate: servo natural frequency x timestep, stability margin of the explicit kp term
SERVO_DAMPING_RATIO = 1.0  # estimate
FORCE_Z_DAMPING_RATIO = 0.5  # estimate: z-joint damping in force control, relative to the contact mode


@dataclass(frozen=True)
class ContactDesign:
    """Numbers behind the MJCF (all SI); built by `contact_design(cfg)`.

    pad_stiffness_n_per_m: Winkler estimate k = E * A_contact / thickness of the pad under the indenter.
    contact_points: contact points MuJoCo makes between indenter and pad (4 box-box, 1 sphere-box).
    mass_xy_kg, mass_z_kg: effective (mass + armature) of the x/y and z slide joints.
    invweight: translational body_invweight0 of the indenter (1/kg), as MuJoCo computes it.
    solref: (-stiffness, -damping), direct form, per contact point.
    impedance: solimp dmin = dmax.
    servo_kp_n_per_m, servo_kv_n_s_per_m: gains of the x/y (and z in displacement control) position actuators.
    z_damping_n_s_per_m: passive damping on the z joint (force control only; 0 otherwise).
    """

    pad_stiffness_n_per_m: float
    contact_points: int
    mass_xy_kg: float
    mass_z_kg: float
    invweight: float
    solref: tuple[float, float]
    impedance: float
    servo_kp_n_per_m: float
    servo_kv_n_s_per_m: float
    z_damping_n_s_per_m: float


def contact_area_m2(cfg: SceneConfig) -> float:
    """Area over which the pad carries the indenter (Winkler estimate).

    Box: the footprint clipped to the pad. Sphere: at a reference depth delta (mid amplitude; for
    force control the depth that carries the mid force), the secant stiffness of F = (E / t) pi R delta^2.  # estimate (the sphere is linearised)
    """
    pad, ind, prot = cfg.pad, cfg.indenter, cfg.protocol
    if ind.shape == "box":
        return min(ind.size_x_m, pad.size_x_m) * min(ind.size_y_m, pad.size_y_m)
    mid = 0.5 * (prot.amplitude_min + prot.amplitude_max)
    if prot.control == "displacement":
        delta = mid
    else:
        delta = math.sqrt(mid * pad.thickness_m / (pad.youngs_modulus_pa * math.pi * ind.radius_m))
    delta = min(max(delta, 1e-6), ind.radius_m)
    return math.pi * ind.radius_m * delta


def contact_design(cfg: SceneConfig) -> ContactDesign:
    """Choose armature, servo gains and solref so MuJoCo's contact stiffness matches the pad's Winkler stiffness."""
    dt = cfg.sampling.physics_timestep_s
    k_pad = cfg.pad.youngs_modulus_pa * contact_area_m2(cfg) / cfg.pad.thickness_m
    kp = SERVO_STIFFNESS_RATIO * k_pad
    # explicit kp term: stable for sqrt(kp / m) * dt ~ SERVO_OMEGA_DT -> raise the effective mass (armature)
    mass_servo = max(cfg.indenter.mass_kg, kp * dt * dt / SERVO_OMEGA_DT**2)
    kv = 2.0 * SERVO_DAMPING_RATIO * math.sqrt(kp * mass_servo)
    force_ctrl = cfg.protocol.control == "force"
    d = CONTACT_IMPEDANCE
    if force_ctrl:
        # no z servo: keep the z inertia small so the commanded force reaches the pad; only the contact
        # spring must stay stable: in-contact mode sqrt(k_pad (1-d) / m) * dt ~ SERVO_OMEGA_DT
        mass_z = max(cfg.indenter.mass_kg, k_pad * (1 - d) * dt * dt / SERVO_OMEGA_DT**2)
    else:
        mass_z = mass_servo
    invweight = (2.0 / mass_servo + 1.0 / mass_z) / 3.0
    n_points = 4 if cfg.indenter.shape == "box" else 1
    stiff = k_pad * (1.0 - d) * invweight / n_points
    # contact damping force ~ n * damp / invweight * v; aim at CONTACT_DAMPING_RATIO of the contact mode
    damp = 2.0 * CONTACT_DAMPING_RATIO * math.sqrt(k_pad * mass_z) * invweight / n_points
    # force control: nothing else damps the indenter's z motion; the joint damping acts only while it moves
    z_damp = 2.0 * FORCE_Z_DAMPING_RATIO * math.sqrt(k_pad * mass_z) if force_ctrl else 0.0
    return ContactDesign(
        pad_stiffness_n_per_m=k_pad,
        contact_points=n_points,
        mass_xy_kg=mass_servo,
        mass_z_kg=mass_z,
        invweight=invweight,
        solref=(-stiff, -damp),
        impedance=d,
        servo_kp_n_per_m=kp,
        servo_kv_n_s_per_m=kv,
        z_damping_n_s_per_m=z_damp,
    )


def _indenter_geom(cfg: SceneConfig, suffix: str = "") -> str:
    ind = cfg.indenter
    if ind.shape == "box":
        h = INDENTER_BOX_THICKNESS_M / 2
        return (
            f'<geom name="indenter{suffix}" type="box" size="{ind.size_x_m / 2!r} {ind.size_y_m / 2!r} {h!r}" '
            f'pos="0 0 {h!r}" mass="{ind.mass_kg!r}" contype="0" conaffinity="0" rgba="0.6 0.6 0.7 1"/>'
        )
    r = ind.radius_m
    return (
        f'<geom name="indenter{suffix}" type="sphere" size="{r!r}" pos="0 0 {r!r}" mass="{ind.mass_kg!r}" '
        f'contype="0" conaffinity="0" rgba="0.6 0.6 0.7 1"/>'
    )


def indenter_suffix(i: int) -> str:
    """Name suffix of indenter i: "" for the first (the single-indenter scene), then "1", "2", ..."""
    return "" if i == 0 else str(i)


SENSORS_PER_INDENTER = 3 + 17  # jointpos x, y, z + contact netforce


def build_mjcf(cfg: SceneConfig) -> str:
    """MJCF string of the scene. Actuators: x, y position servos; z position servo (displacement
    control, ctrl = target height of the indenter's lowest point, m) or z motor (force control,
    ctrl = vertical force on the indenter, N, negative = into the pad). Sensors, in order:
    jointpos x, y, z (3), then the contact sensor with reduce="netforce" (found, force(3), torque(3),
    dist, pos(3), normal(3), tangent(3): 17 values, force = force on the pad, global frame).

    With indenter.count = n > 1 the scene holds n identical indenters (bodies indenter, indenter1, ...),
    each with its own joints, actuators (x, y, z per indenter, in that order) and sensors
    (SENSORS_PER_INDENTER values per indenter, in indenter order); indenters do not touch each other.
    """
    pad, ind = cfg.pad, cfg.indenter
    des = contact_design(cfg)
    mu = ind.friction
    m = ind.mass_kg
    arm_xy = des.mass_xy_kg - m
    arm_z = des.mass_z_kg - m
    kp, kv = des.servo_kp_n_per_m, des.servo_kv_n_s_per_m
    hx, hy, hz = pad.size_x_m / 2, pad.size_y_m / 2, pad.thickness_m / 2
    d = des.impedance
    bodies, pairs, acts, sens = [], [], [], []
    for i in range(ind.count):
        x = indenter_suffix(i)
        if cfg.protocol.control == "displacement":
            z_act = f'<position name="act_z{x}" joint="slide_z{x}" kp="{kp!r}" kv="{kv!r}"/>'
        else:
            z_act = f'<motor name="act_z{x}" joint="slide_z{x}" gear="1"/>'
        bodies.append(f"""    <body name="indenter{x}" pos="0 0 {pad.thickness_m!r}" gravcomp="1">
      <joint name="slide_x{x}" type="slide" axis="1 0 0" armature="{arm_xy!r}"/>
      <joint name="slide_y{x}" type="slide" axis="0 1 0" armature="{arm_xy!r}"/>
      <joint name="slide_z{x}" type="slide" axis="0 0 1" armature="{arm_z!r}" damping="{des.z_damping_n_s_per_m!r}"/>
      {_indenter_geom(cfg, x)}
    </body>
""")
        pairs.append(f"""    <pair name="press{x}" geom1="indenter{x}" geom2="pad" condim="3" friction="{mu!r} {mu!r} 0.005 0.0001 0.0001"
          solref="{des.solref[0]!r} {des.solref[1]!r}" solimp="{d!r} {d!r} 0.001 0.5 2"/>
""")
        acts.append(f"""    <position name="act_x{x}" joint="slide_x{x}" kp="{kp!r}" kv="{kv!r}"/>
    <position name="act_y{x}" joint="slide_y{x}" kp="{kp!r}" kv="{kv!r}"/>
    {z_act}
""")
        sens.append(f"""    <jointpos name="pos_x{x}" joint="slide_x{x}"/>
    <jointpos name="pos_y{x}" joint="slide_y{x}"/>
    <jointpos name="pos_z{x}" joint="slide_z{x}"/>
    <contact name="press_net{x}" geom1="indenter{x}" geom2="pad" data="found force torque dist pos normal tangent"
             reduce="netforce"/>
""")
    return f"""<mujoco model="piezotwin_{cfg.name}">
  <option timestep="{cfg.sampling.physics_timestep_s!r}" integrator="implicitfast" cone="elliptic"/>
  <worldbody>
    <geom name="pad" type="box" size="{hx!r} {hy!r} {hz!r}" pos="0 0 {hz!r}" contype="0" conaffinity="0"
          rgba="0.2 0.2 0.2 1"/>
{"".join(bodies)}  </worldbody>
  <contact>
{"".join(pairs)}  </contact>
  <actuator>
{"".join(acts)}  </actuator>
  <sensor>
{"".join(sens)}  </sensor>
</mujoco>
"""


def shear_stiffness_n_per_m(cfg: SceneConfig) -> float:
    """Tangential (stick) stiffness of the pad under one indenter: a sheared layer, k_t = G A / h with
    G = E / (2 (1 + nu)) (Timoshenko & Goodier, Theory of Elasticity, 1970; Johnson 1985 sect. 7.2 for the
    stick regime of a tangentially loaded contact). Used by the Coulomb stick-slip model of the
    "press_stroke" stage (simulate/contact/press_stroke.py)."""
    g = cfg.pad.youngs_modulus_pa / (2.0 * (1.0 + cfg.pad.poisson_ratio))
    return g * contact_area_m2(cfg) / cfg.pad.thickness_m
