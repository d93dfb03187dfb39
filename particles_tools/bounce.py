"""The dropped ball of issue 14: a point bouncing on a plane or off a sphere (onto the ground), with
or without linear drag, integrated by :func:`engine.ode.solve` with its impacts located
(:mod:`engine.ode.events`), against a closed form or scipy ``solve_ivp`` with ``events``.

State y = (x, y, z, vx, vy, vz) (m, m/s), y' = (v, g − c·v) with g = (0, −9.8125, 0) (exact in
binary) and drag c = 0 or 0.5 1/s. Scenes (:data:`SCENES`): ``plane`` — dropped from rest 1 m
above the ground y = 0; ``sphere`` — dropped from rest at (0.3, 2, 0) onto a sphere of radius
0.5 at (0, 0.5, 0) (first impact at (0.3, 0.9, 0), normal (0.6, 0.8, 0)), which throws it
sideways onto the ground. Restitution e = 0.8, no friction.

References: without drag on the plane, the closed form (NUMERICS.md, "Collisions"): first impact
t₁ = √(2y₀/g) at speed v₁ = g t₁, then flights of 2eᵏv₁/g; otherwise scipy's DOP853 at rtol
1e-12 stopped at each impact by ``events`` (the surface crossed inward), the velocity reflected
there and the run restarted (the reference's own error ≲ 1e-10 m).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import taichi as ti

G = 9.8125  # m/s² (exact in binary)
E = 0.8  # restitution
DRAG = 0.5  # 1/s, when on
T_END = 2.0  # s: where the targets measure the error


@dataclass(frozen=True)
class BounceScene:
    name: str
    y0: tuple  # (x, y, z, vx, vy, vz)
    specs: tuple  # (kind, point, normal or radius)


SCENES = {
    "plane": BounceScene("plane", (0.0, 1.0, 0.0, 0.0, 0.0, 0.0), (("plane", (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),)),
    "sphere": BounceScene("sphere", (0.3, 2.0, 0.0, 0.0, 0.0, 0.0),
                          (("sphere", (0.0, 0.5, 0.0), 0.5), ("plane", (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)))),
}


def ball_rhs(drag: bool):
    """The ``@ti.func`` f(y, t) of the ball (module docstring)."""
    c = DRAG if drag else 0.0

    @ti.func
    def f(y, t):
        d = y * 0
        for k in ti.static(range(3)):
            d[k] = y[3 + k]
            d[3 + k] = -c * y[3 + k]
        d[4] -= G
        return d

    return f


_RHS = {}
_COLLIDERS = {}


def colliders(scene: str):
    """The scene's :class:`~engine.colliders.Colliders` in f64 (built once per Taichi session)."""
    from engine.colliders import ColliderSpec, Colliders

    if scene not in _COLLIDERS:
        specs = []
        for kind, point, extra in SCENES[scene].specs:
            if kind == "plane":
                specs.append(ColliderSpec("plane", point=point, normal=extra, restitution=E))
            else:
                specs.append(ColliderSpec("sphere", point=point, radius=extra, restitution=E))
        _COLLIDERS[scene] = Colliders(specs, dtype=ti.f64)
    return _COLLIDERS[scene]


def _forget():
    _COLLIDERS.clear()


def run(scene: str, drag: bool, *, tol=None, h=None, method="rk4", t_end=T_END, t_eval=None, **kw):
    """:func:`engine.ode.solve` of the ball with located impacts (``tol``: adaptive, rtol = atol
    = tol; else fixed ``h``)."""
    from engine.ode import solve
    from engine.runtime import on_reset

    if drag not in _RHS:
        _RHS[drag] = ball_rhs(drag)
        on_reset(_forget)
    return solve(_RHS[drag], SCENES[scene].y0, (0.0, t_end), method=method, h=h, tol=tol,
                 events=colliders(scene), t_eval=t_eval, **kw)


# -- references -----------------------------------------------------------------------------------
def plane_closed_form(t: float, y0: float = 1.0, e: float = E, g: float = G):
    """(height, vertical velocity, impact times up to t) of a ball dropped from rest at y0 onto
    y = 0 without drag (NUMERICS.md, "Collisions")."""
    t1 = math.sqrt(2 * y0 / g)
    if t < t1:
        return y0 - 0.5 * g * t * t, -g * t, []
    impacts, start, v = [t1], t1, e * g * t1
    while start + 2 * v / g <= t and v > 1e-300:
        start += 2 * v / g
        impacts.append(start)
        v *= e
    s = t - start
    return v * s - 0.5 * g * s * s, v - g * s, impacts


def _scipy_rhs(c):
    def f(t, y):
        return np.concatenate([y[3:], -c * y[3:] - np.array([0.0, G, 0.0])])
    return f


def _contact_np(spec, x):
    kind, point, extra = spec
    if kind == "plane":
        N = np.asarray(extra, float)
        return float((x - point) @ N), N
    d = x - np.asarray(point, float)
    return float(np.linalg.norm(d) - extra), d / np.linalg.norm(d)


def scipy_reference(scene: str, drag: bool, t_end: float = T_END, rtol: float = 1e-12):
    """(state at t_end, impact times) from scipy's DOP853 stopped at each impact (module
    docstring)."""
    from scipy.integrate import solve_ivp

    sc = SCENES[scene]
    f = _scipy_rhs(DRAG if drag else 0.0)
    events = []
    for spec in sc.specs:
        def ev(t, y, spec=spec):
            return _contact_np(spec, y[:3])[0]
        ev.terminal, ev.direction = True, -1.0
        events.append(ev)
    t, y, impacts = 0.0, np.array(sc.y0, float), []
    while t < t_end:
        # max_step: scipy looks for sign changes at step ends only, and a long step of a
        # ballistic path could pass through the sphere's cap unseen
        r = solve_ivp(f, (t, t_end), y, method="DOP853", rtol=rtol, atol=rtol, events=events, max_step=0.01)
        t, y = float(r.t[-1]), r.y[:, -1].copy()
        if r.status != 1:
            break
        k = next(i for i, te in enumerate(r.t_events) if len(te))
        _g, N = _contact_np(sc.specs[k], y[:3])
        vn = y[3:] @ N
        y[3:] -= (1 + E) * vn * N  # v' = v_t − e v_n (no friction)
        impacts.append(t)
        if len(impacts) > 200:
            raise RuntimeError("scipy reference: Zeno tail before t_end")
    return y, impacts


_ref_cache: dict = {}


def reference(scene: str, drag: bool, t_end: float = T_END) -> np.ndarray:
    """The ball's state at t_end: the closed form for the plane without drag, else scipy's."""
    key = (scene, drag, t_end)
    if key not in _ref_cache:
        if scene == "plane" and not drag:
            hgt, vy, _ = plane_closed_form(t_end)
            _ref_cache[key] = np.array([0.0, hgt, 0.0, 0.0, vy, 0.0])
        else:
            _ref_cache[key] = scipy_reference(scene, drag, t_end)[0]
    return _ref_cache[key]


def position_error(r, scene: str, drag: bool) -> float:
    """Max-norm position error (m) of a solve result's last state against the reference."""
    return float(np.abs(r.y[:3, -1] - reference(scene, drag, float(r.t[-1]))[:3]).max())


def particle_scene(scene: str, drag: bool, solver: dict, contacts: bool = False, fps: int = 60):
    """The same ball as one particle of a :class:`engine.api.ParticleScene` (float32), with the
    scene's ``solver`` table (e.g. ``{"integrator": "rk4", "h": 1/240, "impacts": "projected"}``)."""
    from engine.api import SceneBuilder

    sc = SCENES[scene]
    b = (SceneBuilder(seed=1, fps=fps).solver(**solver)
         .forces(gravity=[0.0, -G, 0.0], drag=DRAG if drag else 0.0)
         .emitter(name="ball", shape="point", position=list(sc.y0[:3]), speed=[0.0, 0.0], lifetime=100.0,
                  bursts=[{"time": 0.0, "count": 1}], rate=0.0))
    for k, (kind, point, extra) in enumerate(sc.specs):
        if kind == "plane":
            b = b.collider(type="plane", name=f"c{k}", point=list(point), normal=list(extra), restitution=E)
        else:
            b = b.collider(type="sphere", name=f"c{k}", center=list(point), radius=extra, restitution=E)
    return b.build(contacts=contacts, render=False)


def scene_error(scene: str, drag: bool, solver: dict, t_end: float = T_END, fps: int = 60):
    """(position error at t_end in m, steps taken) of :func:`particle_scene` stepped frame by
    frame."""
    s = particle_scene(scene, drag, solver, fps=fps)
    for _ in range(round(t_end * fps)):
        s.step(1.0 / fps)
    steps = s.scene.stats.steps
    err = float(np.abs(s.particles()["position"][0].astype(np.float64) - reference(scene, drag, t_end)[:3]).max())
    s.close()
    return err, steps
