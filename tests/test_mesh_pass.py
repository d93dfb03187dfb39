"""The mesh pass's vertices: a soft body's nodes read from its own field inside the pass's launch,
a host's drawable given through ``positions`` copied in by the host, and both in one renderer,
each body's rows at its offset — always the image drawn through ``positions``."""
import os

import numpy as np
import pytest

from helpers import ROOT, drawn_scene

from engine.config import load_config
from engine.render.renderer import Renderer


class _NoField:
    """A body as a host's own drawable would be: its vertices through ``positions`` only."""

    def __init__(self, body):
        self.body = body

    def drawables(self):
        d = dict(self.body.drawables())
        d.pop("position_field")
        return d


@pytest.mark.slow
def test_the_mesh_pass_reads_a_soft_bodys_nodes_as_positions_gives_them():
    """A soft body's mesh pass copies the nodes from the body's own field inside its launch (no
    to_numpy / from_numpy a frame): the image is the one drawn through ``positions``, frame after
    frame as the cloth falls (checked to fail with the copy left out of the pass: nothing is
    drawn)."""
    s = drawn_scene("configs/cloth.toml", frames=0, size=(192, 108))
    body = s.bodies[0]
    assert s.renderer.mesh.fields and not s.renderer.mesh.host_copy
    host = Renderer(None, [], s.colliders, s.cfg.render, bodies=[_NoField(body)])
    assert host.mesh.host_copy and not host.mesh.fields
    first = None
    for k in range(4):
        for _ in range(8):
            s.advance_frame()
        img = s.render(192, 108).copy()
        assert np.array_equal(img, host.render(s.camera, 192, 108)), k
        first = img if first is None else first
    assert not np.array_equal(first, img)  # the body moved (not vacuous)


class _Triangles:
    """A host's own drawable: two triangles facing the camera, their six vertices in a Taichi
    field of ``rows`` rows, given as ``position_field`` (``with_field``) or through
    ``positions`` only."""

    def __init__(self, field, with_field=True):
        self.field, self.with_field = field, with_field

    def drawables(self):
        d = dict(kind="mesh", positions=lambda: np.resize(self.field.to_numpy(), (6, 3)),
                 triangles=np.array([[0, 1, 2], [3, 4, 5]], np.int32), lines=np.zeros((0, 2), np.int32),
                 color=(0.8, 0.4, 0.2))
        if self.with_field:
            d["position_field"] = self.field
        return d


def test_the_mesh_pass_draws_a_field_as_its_positions_give_it():
    """A drawable's ``position_field`` is copied in by the mesh pass itself (no NumPy a frame):
    the image is the one drawn through ``positions``, and follows the field when it changes
    (checked to fail with the pass's copy left out: nothing is drawn). A field shorter than the
    vertices is refused with one line naming it, nothing read past its end."""
    import taichi as ti
    from engine.render.camera import Camera

    cfg = load_config(os.path.join(ROOT, "configs/cloth.toml")).render
    field = ti.Vector.field(3, ti.f32, shape=8)  # (two spare rows past the six vertices)
    own, host = (Renderer(None, [], None, cfg, bodies=[_Triangles(field, w)]) for w in (True, False))
    assert own.mesh.fields and not own.mesh.host_copy and host.mesh.host_copy and not host.mesh.fields
    cam = Camera((0.0, 0.5, 3.0), (0.0, 0.5, 0.0), 45.0)
    tri = np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.8, 0.0]], np.float32)
    images = []
    for shift in (0.0, 0.4):
        field.from_numpy(np.concatenate([tri + [shift - 0.6, 0.0, 0.0], tri + [shift, 0.1, 0.2],
                                         np.zeros((2, 3), np.float32)]).astype(np.float32))
        images.append(own.render(cam, 96, 54).copy())
        assert np.array_equal(images[-1], host.render(cam, 96, 54)), shift
    assert not np.array_equal(images[0], images[1])  # drawn, and moved with the field (not vacuous)
    with pytest.raises(ValueError, match=r"^drawables: position_field holds \(5,\) rows, fewer than the 6 "):
        Renderer(None, [], None, cfg, bodies=[_Triangles(ti.Vector.field(3, ti.f32, shape=5))])


@pytest.mark.slow
def test_the_mesh_pass_puts_each_bodys_nodes_at_its_offset():
    """Two soft bodies of two scenes (a chain, then a cloth) in one renderer: drawn through their
    fields (the cloth's rows after the chain's), and with the chain given through ``positions``
    only (the host copies the chain's rows, the pass the cloth's), the images are the ones drawn
    with both through ``positions``."""
    a = drawn_scene("configs/chain.toml", frames=0, size=(192, 108))
    b = drawn_scene("configs/cloth.toml", frames=0, size=(192, 108))
    chain, cloth = a.bodies[0], b.bodies[0]
    make = lambda bodies: Renderer(None, [], b.colliders, b.cfg.render, bodies=bodies)  # noqa: E731
    fields, mixed, host = make([chain, cloth]), make([_NoField(chain), cloth]), make([_NoField(chain), _NoField(cloth)])
    assert [f[1] for f in fields.mesh.fields] == [0, chain.node_count] and not fields.mesh.host_copy
    assert [f[1] for f in mixed.mesh.fields] == [chain.node_count] and mixed.mesh.host_copy
    for k in range(3):
        for _ in range(8):
            a.advance_frame()
            b.advance_frame()
        ref = host.render(b.camera, 192, 108).copy()
        assert np.array_equal(fields.render(b.camera, 192, 108), ref), k
        assert np.array_equal(mixed.render(b.camera, 192, 108), ref), k
    # the chain is in view: a pass that put the cloth's rows over the chain's would show
    assert not np.array_equal(make([_NoField(cloth)]).render(b.camera, 192, 108), ref)
