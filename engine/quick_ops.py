"""Taichi's vector reductions (``v.dot(w)``, ``v.sum()``, ``v.norm()``, ``v.norm_sqr()``,
``v.cross(w)``, ``v.normalized()``) built without inlining a function, for the front end's sake.

Inside a kernel, ``v.dot(w)`` is Taichi's ``matrix_ops.dot``, a ``@pyfunc``: each call is parsed
from source and its AST transformed again where it is inlined — ``dot`` inlines ``sum``, which
inlines ``_reduce`` — on every start, also when the kernel then comes from the offline cache.
The front end's cost is per node transformed: sparks' located step calls them ~250 times (77
``sum``s), a third of its front-end time. Each replacement below builds the same operations in
the same order, as those functions' bodies do, with the same local copies: each argument copied
(an inlined function takes it by value) and each assignment through a temporary, then the
products and the left-to-right sum (``_reduce``), the square root, the cross product's three
differences, ``1 / (norm + eps) * v``. (The copies matter: a first version without them moved
campfire's particles by an ulp after a few steps; LLVM's fast-math code depends on the shape of
what it is given.) No function is inlined, so none is parsed or transformed.

Any call these do not cover (Python scope, a matrix rather than a vector where a vector is
wanted, shapes that do not match, a non-tensor argument) goes to Taichi's own function, which
computes it or raises its own error. Frames are byte-identical with and without them
(tests/test_startup.py; the configs' frames hashed both ways), though the kernels' offline-cache
keys change once (the front end's IR has no function scopes for them).
"""
from __future__ import annotations

NAMES = ("sum", "norm_sqr", "norm", "dot", "cross", "normalized")


def install() -> bool:
    """Put the replacements in ``taichi.lang.matrix_ops`` (where the front end looks a tensor's
    method up); False where that module is not Taichi 1.7's (left alone). Idempotent."""
    try:
        from taichi.lang import expr, impl, matrix_ops
        from taichi.lang import ops as tops
        from taichi.lang.matrix import make_matrix
    except ImportError:  # pragma: no cover - another Taichi version
        return False
    if getattr(matrix_ops.sum, "quick", False):
        return True
    if not all(hasattr(matrix_ops, n) for n in NAMES):  # pragma: no cover
        return False
    original = {n: getattr(matrix_ops, n) for n in NAMES}

    def tensor_shape(x):
        """x's shape if it is a tensor expression inside a kernel, else None."""
        if isinstance(x, expr.Expr) and x.ptr.is_tensor():
            return tuple(x.get_shape())
        return None

    copy = local  # (an inlined function's argument, passed by value)

    def item(x, *index):
        return impl.subscript(None, x, *index)

    def reduce_sum(mat, shape):
        """``_reduce(mat, ops.add)``'s body, ``mat`` its argument: ``result = mat[0]``, then
        ``result = result + mat[i]`` for each further entry in row-major order, each assignment
        as the front end builds one (the value into a temporary, then into the variable)."""
        cells = [(i,) for i in range(shape[0])] if len(shape) == 1 else \
            [(i, j) for i in range(shape[0]) for j in range(shape[1])]
        result = copy(copy(item(mat, *cells[0])))
        for c in cells[1:]:
            result._assign(copy(tops.add(result, item(mat, *c))))
        return result

    def sum_of(mat, shape):
        """``sum(mat)``: its argument by value, passed on to ``_reduce``, by value again."""
        return reduce_sum(copy(copy(mat)), shape)

    def norm_of(mat, eps, shape):
        """``norm(mat, eps)`` = sqrt(norm_sqr(mat) + eps), norm_sqr(m) = sum(m * m)."""
        m, e = copy(mat), copy(eps)
        m2 = copy(m)
        return tops.sqrt(sum_of(m2 * m2, shape) + e)

    def quick(name, fn):
        def wrapped(*args, **kwargs):
            if impl.inside_kernel():
                got = fn(*args, **kwargs)
                if got is not None:
                    return got
            return original[name](*args, **kwargs)

        wrapped.__name__ = wrapped.__qualname__ = name
        wrapped.__module__ = matrix_ops.__name__  # (the front end's test for Taichi's own functions)
        wrapped.__doc__ = original[name].__doc__
        wrapped.quick = True
        return wrapped

    def q_sum(mat):
        shape = tensor_shape(mat)
        if shape is None or len(shape) not in (1, 2):
            return None
        return sum_of(mat, shape)

    def q_norm_sqr(mat):
        shape = tensor_shape(mat)
        if shape is None or len(shape) not in (1, 2):
            return None
        m = copy(mat)
        return sum_of(m * m, shape)

    def q_norm(mat, eps=0.0):
        shape = tensor_shape(mat)
        if shape is None or len(shape) not in (1, 2):
            return None
        return norm_of(mat, eps, shape)

    def vectors(x, y):
        sx, sy = tensor_shape(x), tensor_shape(y)
        return sx is not None and sx == sy and len(sx) == 1

    def q_dot(vec_x, vec_y):
        if not vectors(vec_x, vec_y):
            return None
        x, y = copy(vec_x), copy(vec_y)
        return sum_of(x * y, tensor_shape(vec_x))

    def q_cross(vec_x, vec_y):
        if not vectors(vec_x, vec_y) or tensor_shape(vec_x)[0] != 3:
            return None
        x, y = copy(vec_x), copy(vec_y)
        a = [item(x, i) for i in range(3)]
        b = [item(y, i) for i in range(3)]
        return make_matrix([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])

    def q_normalized(vec, eps=0.0):
        shape = tensor_shape(vec)
        if shape is None or len(shape) != 1:
            return None
        v, e = copy(vec), copy(eps)
        invlen = copy(copy(1 / (norm_of(v, 0.0, shape) + e)))  # (an assignment: see reduce_sum)
        return invlen * v

    for name, fn in zip(NAMES, (q_sum, q_norm_sqr, q_norm, q_dot, q_cross, q_normalized)):
        setattr(matrix_ops, name, quick(name, fn))
    matrix_ops.quick_originals = original
    return True


def local(x):
    """x put into a local variable, as a ``ti.func``'s argument or assignment puts it: later uses
    read the variable (an expression used twice is otherwise built twice when the kernel is
    lowered). Taichi scope only."""
    from taichi.lang import impl

    return impl.expr_init(x)


def inline(fn):
    """Marks ``fn``, a plain Python function of Taichi expressions, as one to call inside kernels.
    The front end runs a plain function at compile time on its arguments' expressions, so its
    operations are built where it is called and nothing is parsed or transformed (a ``ti.func`` is
    parsed and transformed again at each call site, at every start). Only for code whose values do
    not depend on the IR's shape — integer operations, exact scalings — unless it copies as a
    ``ti.func`` does (:func:`local`; see above). A value used more than once should go through
    :func:`local` all the same, or it is built once per use. The front end warns at a call of a
    function it does not take for Taichi's own; the mark is what it checks (``_is_taichi_function``;
    it then reads ``fn.func.has_print``). Idempotent."""
    fn._is_taichi_function = True
    fn.func, fn.has_print = fn, False
    return fn
