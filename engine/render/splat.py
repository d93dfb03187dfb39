"""What one sprite adds to one pixel, and the accumulators it adds to.

A sprite disc of radius r px centred at (cx, cy) weighs w = (1 − d²/r²)² · energy · fade at a pixel
centre d away (a polynomial falloff: no ``exp``), where fade = min(1, gap/soft) is the
soft-particle depth fade over ``soft`` metres in front of an opaque surface (Lorach 2007).

Per pixel there are two accumulators, vec4 f32 each:
* ``A`` = (additive light L (RGB), transmittance T): additive sprites add col·α·w to L; each
  alpha-blended sprite multiplies T by (1 − α') with α' = min(0.98, α·w). A running product
  instead of a sum of logs (McGuire & Bavoil keep Σ log(1 − α)): the same T without a
  transcendental per pixel.
* ``B`` = (Σ col·α'·w_z, Σ α'·w_z): weighted blended order-independent transparency
  (McGuire & Bavoil 2013), w_z the depth weight of eq. 10.
Sums and one product: the pixel does not depend on the order of sprites in the pool, so no sort.
Once T < 1e-4 (the pixel is opaque with smoke) further alpha sprites are skipped (3DGS's early
stop); additive light still adds.
"""
import taichi as ti

T_OPAQUE = 1e-4


@ti.func
def disc_weight(xx, yy, cx, cy, inv_r2, z, depth_here, energy, inv_soft):
    """Weight of the disc at pixel (xx, yy); 0 outside it or behind the opaque depth."""
    dx = xx + 0.5 - cx
    dy = yy + 0.5 - cy
    q = 1.0 - (dx * dx + dy * dy) * inv_r2
    gap = depth_here - z
    return ti.select(q > 0 and gap > 0, q * q * energy * ti.min(1.0, gap * inv_soft), 0.0)


@ti.func
def add_sprite(A, B, w, col, a, is_add, wzf, uses_add: ti.template(), uses_alpha: ti.template()):
    """(A, B) after one sprite of weight w at this pixel (see the module docstring)."""
    if ti.static(uses_add):
        if is_add:
            A = A + ti.Vector([col[0], col[1], col[2], 0.0]) * (a * w)
    if ti.static(uses_alpha):
        if not is_add and A[3] >= T_OPAQUE:
            aa = ti.min(0.98, a * w)
            wz = aa * wzf
            B = B + ti.Vector([col[0] * wz, col[1] * wz, col[2] * wz, wz])
            A[3] = A[3] * (1.0 - aa)
    return A, B


@ti.func
def capsule_point(xx, yy, rec):
    """For a streak record (kind −1): the point of its segment nearest to the centre of pixel
    (xx, yy), and the alpha factor there (1 at the head, 0.4 at the tail: the motion blur fades)."""
    dx, dy = rec[9] - rec[0], rec[10] - rec[1]
    t = ti.math.clamp(((xx + 0.5 - rec[0]) * dx + (yy + 0.5 - rec[1]) * dy) * rec[15], 0.0, 1.0)
    return rec[0] + t * dx, rec[1] + t * dy, 1.0 - 0.6 * t


@ti.func
def record_box(rec):
    """Pixel-space bounding box (x0, y0, x1, y1) of a record's disc or capsule, as floats."""
    r = rec[2]
    x_lo, x_hi, y_lo, y_hi = rec[0], rec[0], rec[1], rec[1]
    if rec[12] < 0:
        x_lo, x_hi = ti.min(rec[0], rec[9]), ti.max(rec[0], rec[9])
        y_lo, y_hi = ti.min(rec[1], rec[10]), ti.max(rec[1], rec[10])
    return x_lo - r, y_lo - r, x_hi + r, y_hi + r
