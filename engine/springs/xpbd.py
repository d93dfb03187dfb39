"""XPBD: extended position-based dynamics (Macklin, Müller & Chentanez 2016) for springs.

Each spring is a distance constraint C = |x_a − x_b| − r with compliance α = 1/ks; per step of h
α̃ = α/h², and spring damping kd enters as the paper's β: γ = α̃·(h²β)/h = kd/(ks·h). Per step:

    v += h g (free nodes); x_prev = x; x += h v; λ = 0
    repeat `iterations` times, colour by colour (Gauss–Seidel, race-free, deterministic):
        Δλ = (−C − α̃λ − γ ∇C·(x − x_prev)) / ((1 + γ)(w_a + w_b) + α̃)
        λ += Δλ;  x_a += w_a Δλ n;  x_b −= w_b Δλ n          (n = (x_a − x_b)/|x_a − x_b|)
    v = (x − x_prev)/h

Unconditionally stable for any h: the price is that too few iterations leave stiff springs softer
than ks (sagging), never exploding. Springs with ks = 0 are skipped.
"""
import taichi as ti

from .model import SpringModel, SpringState


class XPBDStepper:
    method = "xpbd"
    order = 1
    fevals = 1

    def __init__(self, model: SpringModel, state: SpringState, iterations: int = 10):
        n, m, dtype, N, M = model.node_count, model.spring_count, model.dtype, max(1, model.node_count), max(1, model.spring_count)
        self.model, self.state, self.iterations = model, state, int(iterations)
        self.x_prev = x_prev = ti.Vector.field(3, dtype, N)
        self.lam = lam = ti.field(dtype, M)
        X, V, w, g = state.node_pos, state.node_vel, model.node_inv_mass, model.gravity
        sa, sb, rl, ks, kd, order = (model.spring_a, model.spring_b, model.spring_rest_length,
                                     model.spring_ks, model.spring_kd, model.color_spring)

        @ti.kernel
        def predict(h: dtype):
            for i in range(n):
                v = V[i]
                if w[i] > 0:
                    v += h * g[None]
                V[i] = v
                x_prev[i] = X[i]
                X[i] += h * v
            for s in range(m):
                lam[s] = 0

        @ti.kernel
        def project_color(lo: ti.i32, hi: ti.i32, h: dtype):
            for q in range(lo, hi):
                s = order[q]
                a, b = sa[s], sb[s]
                wa, wb = w[a], w[b]
                if ks[s] > 0 and wa + wb > 0:
                    L = X[a] - X[b]
                    ln = L.norm()
                    if ln > 1e-12:
                        nrm = L / ln
                        alpha = 1 / (ks[s] * h * h)
                        gamma = kd[s] / (ks[s] * h)
                        C = ln - rl[s]
                        dC = nrm.dot((X[a] - x_prev[a]) - (X[b] - x_prev[b]))
                        dlam = (-C - alpha * lam[s] - gamma * dC) / ((1 + gamma) * (wa + wb) + alpha)
                        lam[s] += dlam
                        X[a] += wa * dlam * nrm
                        X[b] -= wb * dlam * nrm

        @ti.kernel
        def update_velocity(h: dtype):
            for i in range(n):
                V[i] = (X[i] - x_prev[i]) / h

        self._predict, self._project, self._update = predict, project_color, update_velocity

    def step(self, h: float) -> None:
        self._predict(h)
        for _ in range(self.iterations):
            for lo, hi in self.model.color_ranges:
                self._project(lo, hi, h)
        self._update(h)
