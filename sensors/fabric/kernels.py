"""Warp kernel of the per-taxel fabric chain (same equations as sensors/fabric/reference.py, which tests compare).

One thread per (episode, taxel) loops over time with the Prony and play states in registers (the layout
and the time-loop-inside-the-kernel choice of sensors/cnt_pdms/kernels.py; TECH-NOTES: ~7x fewer launches'
worth of overhead on the GPU). Built per (Prony terms, play operators) pair so the term loops unroll.
Source of the physics: paper key `fabric`; Holm, Electric Contacts (1967); Brokate & Sprekels (1996);
Kawabata (1980) for the knit set. A press's draws (kappa, psi) come from a per-episode table built in numpy
(reference.press_draws), so both backends read the same numbers.
"""

# no `from __future__ import annotations`: Warp must see the closure types as real objects

import functools

import numpy as np
import warp as wp

from sensors.fabric.reference import FabricParams, FabricState, press_draws
from sensors.warp_setup import init_warp, resolve_device


@functools.cache
def fabric_kernels(n_prony: int, n_play: int, with_press: bool = True):
    """Kernels for (Prony terms, play operators). with_press=False drops the per-press area and knit set (the
    chain before issue 13; bench/bench_transduction.py times both in one run)."""
    vec_p = wp.types.vector(length=n_prony, dtype=wp.float32)
    vec_k = wp.types.vector(length=n_play, dtype=wp.float32)
    vec5 = wp.types.vector(length=5, dtype=wp.float32)

    @wp.struct
    class Params:
        prony_a: vec_p
        prony_g: vec_p
        play_r: vec_k
        play_w: vec_k
        recovery: float
        n_layers: float
        n_contacts: float
        n_taxels: float
        r_inf: float
        r_amp: float
        inv_fl: float
        beta: float
        rc0: float
        inv_fc: float
        m: float
        f_on: float
        f_off: float
        c_set: float

    def step(p: Params, f: float, q: vec_p, z: vec_k, s: vec5):
        q_new = q
        u = f
        for i in range(n_prony):
            qi = p.prony_a[i] * q[i] + p.prony_g[i] * (1.0 - p.prony_a[i]) * f
            q_new[i] = qi
            u += qi
        w_sum = float(0.0)
        acc = float(0.0)
        z_new = z
        for j in range(n_play):
            zj = wp.max(u - p.play_r[j], wp.min(u + p.play_r[j], z[j]))
            zj = u + (zj - u) * p.recovery
            z_new[j] = zj
            w_sum += p.play_w[j]
            acc += p.play_w[j] * zj
        x = wp.max((1.0 - w_sum) * u + acc, 0.0)
        s_new = s
        kappa = float(1.0)
        if wp.static(with_press):
            xpk = wp.max(x, x + (s[4] - x) * p.c_set)
            s_new[4] = xpk
            x = x + s[3] * (xpk - x)
            kappa = s[2]
        r_layer = p.r_inf + p.r_amp * wp.exp(-wp.pow(x * p.inv_fl, p.beta))
        r_c = p.rc0 * wp.pow(1.0 + x * p.inv_fc, -p.m)
        r_taxel = p.n_taxels * (p.n_layers * r_layer + p.n_contacts * r_c) / kappa
        return q_new, z_new, s_new, x, 1.0 / r_taxel

    tag = f"p{n_prony}_k{n_play}" + ("" if with_press else "_nopress")
    step.__name__ = step.__qualname__ = f"fabric_step_{tag}"
    step_f = wp.func(step)

    def chain(
        load: wp.array(dtype=wp.float32),  # [E*T*N] whole-sample-equivalent force per taxel (N)
        n_steps: int,
        n_taxels: int,
        p: Params,
        st_prony: wp.array(dtype=vec_p),  # [E*N] in/out
        st_play: wp.array(dtype=vec_k),
        st_press: wp.array(dtype=vec5),  # [E*N] (pressed, presses, kappa, psi, x_peak)
        draws: wp.array(dtype=wp.float32),  # [E*M*2] per-press (kappa, psi)
        n_draws: int,
        out_x: wp.array(dtype=wp.float32),  # [E*T*N]
        out_cond: wp.array(dtype=wp.float32),
    ):
        tid = wp.tid()
        ep = tid // n_taxels
        n = tid - ep * n_taxels
        q = st_prony[tid]
        z = st_play[tid]
        s = st_press[tid]
        base = ep * n_steps * n_taxels + n
        for k in range(n_steps):
            idx = base + k * n_taxels
            f = load[idx]
            if wp.static(with_press):
                if s[0] == 0.0 and f > p.f_on:  # a new press: the episode's next draw
                    j = int(s[1]) % n_draws
                    s[2] = draws[(ep * n_draws + j) * 2]
                    s[3] = draws[(ep * n_draws + j) * 2 + 1]
                    s[1] = s[1] + 1.0
                    s[0] = 1.0
                elif s[0] == 1.0 and f < p.f_off:
                    s[0] = 0.0
            q, z, s, x, g = step_f(p, f, q, z, s)
            out_x[idx] = x
            out_cond[idx] = g
        st_prony[tid] = q
        st_play[tid] = z
        st_press[tid] = s

    chain.__name__ = chain.__qualname__ = f"fabric_chain_{tag}"
    k_chain = wp.kernel(chain, module="unique", enable_backward=False)
    return {"chain": k_chain, "Params": Params, "vec_p": vec_p, "vec_k": vec_k, "vec5": vec5}


class FabricChainWarp:
    """Device state for one batch shape; `run` may be called repeatedly (streaming: state carries over)."""

    def __init__(self, p: FabricParams, n_episodes: int, n_taxels: int, device: str = "cpu", with_press: bool = True):
        init_warp()
        self.p, self.E, self.N, self.device = p, n_episodes, n_taxels, resolve_device(device)
        self.k = fabric_kernels(p.n_prony, p.n_play, with_press)
        k, f32 = self.k, np.float32
        s = k["Params"]()
        s.prony_a = k["vec_p"](*p.prony_decay.astype(f32))
        s.prony_g = k["vec_p"](*p.prony_fraction.astype(f32))
        s.play_r = k["vec_k"](*p.play_threshold_n.astype(f32))
        s.play_w = k["vec_k"](*p.play_weight.astype(f32))
        s.recovery = float(p.recovery_decay)
        s.n_layers = float(p.layers)
        s.n_contacts = float(p.layers + 1)
        s.n_taxels = float(p.n_taxels)
        s.r_inf, s.r_amp = float(p.layer_r_inf_ohm), float(p.layer_r_amp_ohm)
        s.inv_fl, s.beta = float(1.0 / p.layer_force_n), float(p.layer_beta)
        s.rc0, s.inv_fc, s.m = float(p.contact_r0_ohm), float(1.0 / p.contact_force_n), float(p.contact_exponent)
        s.f_on, s.f_off, s.c_set = float(p.press_on_n), float(p.press_off_n), float(p.set_decay)
        self.params = s
        self.reset()
        self.set_draws(None)

    def set_draws(self, draws: np.ndarray | None) -> None:
        """Per-press draws [E, M, 2] (reference.press_draws); None: every press the mean one."""
        d = press_draws(None, self.p, self.E) if draws is None else np.asarray(draws, np.float32)
        if d.shape[0] != self.E or d.shape[2] != 2:
            raise ValueError(f"press draws of shape {d.shape}; need ({self.E}, M, 2)")
        self.n_draws = int(d.shape[1])
        self.draws = wp.array(np.ascontiguousarray(d).reshape(-1), dtype=wp.float32, device=self.device)

    def reset(self, state: FabricState | None = None) -> None:
        st = state or FabricState.zeros(self.E * self.N, self.p)
        self.st_prony = wp.array(st.prony_n, dtype=self.k["vec_p"], device=self.device)
        self.st_play = wp.array(st.play_n, dtype=self.k["vec_k"], device=self.device)
        self.st_press = wp.array(st.press, dtype=self.k["vec5"], device=self.device)

    def state(self) -> FabricState:
        return FabricState(self.st_prony.numpy(), self.st_play.numpy(), self.st_press.numpy())

    def run(self, load_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """load_n [E, T, N] -> effective load x [E,T,N] (N) and taxel conductance [E,T,N] (S), float32."""
        E, T, N = load_n.shape
        if (E, N) != (self.E, self.N):
            raise ValueError(f"load shape {load_n.shape} does not match this chain's (episodes={self.E}, taxels={self.N})")
        d = wp.array(np.ascontiguousarray(load_n, np.float32).reshape(-1), dtype=wp.float32, device=self.device)
        out = [wp.empty(E * T * N, dtype=wp.float32, device=self.device) for _ in range(2)]
        wp.launch(self.k["chain"], dim=E * N, inputs=[d, T, N, self.params, self.st_prony, self.st_play, self.st_press, self.draws,
                                                       self.n_draws, out[0], out[1]],
                  device=self.device)
        return out[0].numpy().reshape(E, T, N), out[1].numpy().reshape(E, T, N)
