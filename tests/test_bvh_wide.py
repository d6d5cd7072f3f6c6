"""The scene's wide BVH, "sah8b" (8-wide nodes, oclgi/accel/bvh_wide.py and
the float8 traversal of kernels/bvh.h, with leaves as blocks of 4
triangles, oclgi/accel/bvh_leaf_blocks.py), against brute force and
against the binary traversal of the same tree.

The wide tree holds the binary tree's boxes and leaves, and the traversal
uses the binary walk's slab arithmetic and triangle test: every ray must
give the binary walk's (t, u, v, tri) bit for bit, but where two triangles
lie at exactly the same distance (the same t bits; which one is found first
depends on the order of the visits). It is checked against a float64
brute-force cast on the Cornell box, the bunny and Sponza, with incoherent
rays and with the rays of diffuse bounces.
"""

import re

import numpy as np
import pytest

import oclgi
from oclgi.accel.bvh import any_hits, closest_hits, traversal_work
from oclgi.accel.bvh_build import build_bvh
from oclgi.accel.bvh_wide import MAX_LEAF, WIDE_STACK, collapse
from oclgi.cl.constants import BVH_STACK_SIZE
from oclgi.cl.layout import WIDE
from oclgi.cl.programs import kernel_dir
from oclgi.scene.compiled import CompiledScene
from rays import RAYS, incoherent_rays, unit
from reference import ray_triangle_brute


def _engine(mesh, **light):
    return oclgi.Engine(oclgi.load_dict({
        "mesh": [{"path": str(mesh)}],
        "point_light": [{"position": light.get("at", [0, 0.3, 0]), "intensity": [1, 1, 1]}],
    }))


@pytest.fixture(scope="module")
def cornell(scenes_dir):
    return oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_box.toml"))


@pytest.fixture(scope="module")
def bunny(scenes_dir):
    return _engine(scenes_dir / "stanford-bunny" / "bun_zipper.ply")


@pytest.fixture(scope="module")
def sponza(scenes_dir):
    with pytest.warns(oclgi.OclgiWarning):  # Sponza has one zero-area triangle, dropped with a warning
        return _engine(scenes_dir / "sponza-dabrovic" / "sponza.zip", at=[0, 6, 0])


SCENES = ["cornell", "bunny", "sponza"]


def binary_of(engine):
    """The engine's scene with the binary SAH tree (built once per engine)."""
    if "_binary" not in engine.__dict__:
        engine._binary = CompiledScene(engine.ctx, engine.scene, bvh_quality="sah")
    return engine._binary


def assert_same_as_binary(engine, origins, dirs, tmax=np.inf):
    """The wide traversal's hits (the engine's default tree) equal the
    binary one's bit for bit, but for exact ties (the same t bits, another
    triangle). Returns the tie count."""
    a = closest_hits(engine.queue, binary_of(engine), origins, dirs, tmax)
    b = closest_hits(engine.queue, engine.compiled, origins, dirs, tmax)
    hit = a[3] >= 0
    assert np.array_equal(hit, b[3] >= 0), "hit or miss differs"
    bits = [x.view(np.int32) if x.dtype == np.float32 else x for x in (*a[:3], a[3])]
    bits_w = [x.view(np.int32) if x.dtype == np.float32 else x for x in (*b[:3], b[3])]
    same = np.all([p == q for p, q in zip(bits, bits_w)], axis=0) | ~hit  # a miss has no u, v
    tie = ~same & (bits[0] == bits_w[0]) & (a[3] != b[3])
    assert (same | tie).all(), f"{int((~(same | tie)).sum())} rays differ other than by an exact tie"
    return int(tie.sum())


@pytest.mark.parametrize("rays", list(RAYS))
@pytest.mark.parametrize("name", SCENES)
def test_wide_equals_brute_force_and_binary(request, rng, name, rays):
    """Every ray checked against all triangles in float64 (1,000 rays on
    the large meshes, where brute force is slow), and 100,000 rays against
    the binary traversal bit for bit."""
    engine = request.getfixturevalue(name)
    scene = engine.scene
    wide = engine.compiled
    assert wide.bvh_quality == "sah8b" and wide.bvh_wide  # the default scene tree is the wide one
    n = 1_000 if scene.n_triangles > 1000 else 10_000
    origins, dirs = RAYS[rays](scene, rng, n)
    t, _u, _v, tri = closest_hits(engine.queue, wide, origins, dirs)
    t_ref, tri_ref = ray_triangle_brute(origins, dirs, scene.vertices[scene.faces])
    hit, hit_ref = tri >= 0, tri_ref >= 0
    assert hit_ref.mean() > 0.3
    both = hit & hit_ref
    rel = np.abs(t[both] - t_ref[both]) / np.maximum(t_ref[both], 1e-6)
    # float32 against float64: a ray grazing an edge may hit or miss
    # differently or reach the triangle just behind; 1 in 1,000 at most
    off = (hit != hit_ref).sum() + (rel > 1e-4).sum()
    assert off <= max(2, n // 1000), off
    # another triangle only at the same distance (shared edges, coplanar duplicates)
    assert ((tri[both] == tri_ref[both]) | (rel < 1e-5) | (rel > 1e-4)).all()

    origins, dirs = RAYS[rays](scene, rng, 100_000)
    ties = assert_same_as_binary(engine, origins, dirs)
    assert ties <= 0.005 * len(origins)


def test_axis_aligned_rays_equal_binary(cornell, rng):
    """Directions with zero components (1/d infinite: the slab test's NaN
    case, which the wide walk takes in box.h's own form) from origins on the
    walls' and boxes' planes: the same hits as the binary walk."""
    scene = cornell.scene
    n = 60_000
    verts = scene.vertices[rng.integers(0, len(scene.vertices), n)]
    origins = verts + rng.uniform(-0.3, 0.3, (n, 3)) * scene.diagonal
    # half the origins keep one coordinate of a vertex: on a box's plane
    k = rng.integers(0, 3, n)
    on_plane = rng.random(n) < 0.5
    origins[on_plane, k[on_plane]] = verts[on_plane, k[on_plane]]
    dirs = rng.normal(size=(n, 3))
    zero = rng.random((n, 3)) < 0.4  # each component zero with probability 0.4
    zero[zero.all(axis=1), 0] = False
    dirs[zero] = 0.0
    dirs = unit(dirs)
    assert (dirs == 0).any(axis=1).mean() > 0.5
    t, _u, _v, tri = closest_hits(cornell.queue, cornell.compiled, origins, dirs)
    assert np.isfinite(t).mean() > 0.3
    assert_same_as_binary(cornell, origins, dirs)


def test_any_hit_agrees_with_closest_hit(bunny, rng):
    wide = bunny.compiled
    origins, dirs = incoherent_rays(bunny.scene, rng, 20_000)
    t, _u, _v, tri = closest_hits(bunny.queue, wide, origins, dirs)
    half = np.where(tri >= 0, t * 0.5, 1.0)
    assert not any_hits(bunny.queue, wide, origins, dirs, half).any()
    full = np.where(tri >= 0, t * 1.001, 1.0)
    assert (any_hits(bunny.queue, wide, origins, dirs, full).astype(bool) == (tri >= 0)).all()


def test_limited_rays_equal_binary(bunny, rng):
    """A finite tmax (shadow rays, the locate queries) culls the same in both."""
    origins, dirs = incoherent_rays(bunny.scene, rng, 50_000)
    tmax = rng.uniform(0.0, 0.1, len(origins)).astype(np.float32)
    assert_same_as_binary(bunny, origins, dirs, tmax)


def test_wide_tree_visits_fewer_nodes(bunny, sponza, rng):
    """The counted work: a third of the binary walk's nodes or fewer, the
    triangles tested about the same (the same leaves)."""
    for engine in (bunny, sponza):
        origins, dirs = incoherent_rays(engine.scene, rng, 20_000)
        nodes_w, tests_w = traversal_work(engine.queue, engine.compiled, origins, dirs)
        nodes_b, tests_b = traversal_work(engine.queue, binary_of(engine), origins, dirs)
        assert nodes_w.min() >= 1
        assert nodes_w.sum() < 0.4 * nodes_b.sum()
        assert 0.8 * tests_b.sum() < tests_w.sum() < 1.2 * tests_b.sum()


def test_moved_instance_equals_binary(scenes_dir, rng):
    """Two-level scenes: a moved object's wide tree is traversed in its own
    frame like the binary one, to the same hits."""
    scene = oclgi.load_dict({
        "mesh": [
            {"path": str(scenes_dir / "stanford-bunny" / "bun_zipper.ply"), "movable": True, "name": "bunny",
             "transform": {"scale": 5.0, "translate": [0, 0.2, 0]}},
            {"path": str(scenes_dir / "cornell-box" / "CornellBox-Sphere.obj")},
        ],
        "point_light": [{"position": [0, 1.5, 0], "intensity": [1, 1, 1]}],
    })
    engine = oclgi.Engine(scene)
    binary = binary_of(engine)
    angle = 0.7
    m = np.eye(4)
    m[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    m[:3, 3] = [0.1, 0.05, -0.2]
    k = scene.object_id("bunny")
    engine.compiled.set_transform(engine.queue, k, m)
    binary.set_transform(engine.queue, k, m)
    origins, dirs = incoherent_rays(scene, rng, 50_000)
    t, _u, _v, tri = closest_hits(engine.queue, engine.compiled, origins, dirs)
    a, b = scene.object_ranges()[k]
    assert ((tri >= a) & (tri < b)).mean() > 0.02  # the bunny is hit
    assert_same_as_binary(engine, origins, dirs)


def _walk_need(nodes, root=0):
    """The most stack entries a traversal holds, by walking every path: a
    visit of a node with k used lanes keeps at most k - 1 of them and
    stores a whole vector of WIDE at the top."""
    best, todo = 0, [(root, 0)]
    while todo:
        i, held = todo.pop()
        best = max(best, held + WIDE)
        used = int(np.isfinite(nodes["lox"][i]).sum())
        for c in nodes["child"][i]:
            if c >= 0:
                todo.append((int(c), held + used - 1))
    return best


def _check_wide(bvh, wide):
    """The wide tree regroups the binary one: the same leaves (triangle
    runs), each once, the same boxes, children after their parents, unused
    lanes +inf boxes."""
    b = bvh.nodes
    w = wide.nodes
    leaf = b["count"] > 0
    lo = np.stack([w["lox"], w["loy"], w["loz"]], axis=-1).reshape(-1, 3)
    hi = np.stack([w["hix"], w["hiy"], w["hiz"]], axis=-1).reshape(-1, 3)
    child = w["child"].reshape(-1)
    used = np.isfinite(lo[:, 0])
    assert (np.isinf(lo[~used]).all() and np.isinf(hi[~used]).all() and (lo[~used] > 0).all()
            and (hi[~used] > 0).all())
    assert used.reshape(-1, WIDE).sum(axis=1).min() >= (1 if len(b) == 1 else 2)
    # leaves: exactly the binary leaves, with their boxes
    lanes = used & (child < 0)
    run = ~child[lanes]
    got = sorted(zip((run >> 3).tolist(), ((run & 7) + 1).tolist(), map(tuple, lo[lanes]), map(tuple, hi[lanes])))
    want = sorted(zip(b["first"][leaf].tolist(), b["count"][leaf].tolist(), map(tuple, b["lo"][leaf]),
                      map(tuple, b["hi"][leaf])))
    assert got == want
    # inner lanes: every wide node but the root is one lane's child, after its parent
    inner = used & (child >= 0)
    parent = np.repeat(np.arange(len(w)), WIDE)[inner]
    assert sorted(child[inner].tolist()) == list(range(1, len(w)))
    assert (child[inner] > parent).all()
    # an inner lane's box is the union of its node's lanes
    for lane in np.nonzero(inner)[0]:
        c = child[lane]
        ok = np.isfinite(w["lox"][c])
        for ax, name in enumerate("xyz"):
            assert lo[lane, ax] == w["lo" + name][c][ok].min() and hi[lane, ax] == w["hi" + name][c][ok].max()
    # inner boxes are binary inner boxes: the binary tree's boxes, bit for bit
    inner_b = {(tuple(x), tuple(y)) for x, y in zip(b["lo"][~leaf], b["hi"][~leaf])}
    assert {(tuple(x), tuple(y)) for x, y in zip(lo[inner], hi[inner])} <= inner_b
    assert wide.stack_need == _walk_need(w)


def test_collapse_structure(rng, scenes_dir):
    c = rng.random((5000, 3)) ** 2
    lo, hi = c, c + rng.random((5000, 3)) * 0.02
    for quality in ("sah", "lbvh"):
        bvh = build_bvh(lo, hi, quality=quality)
        wide = collapse(bvh.nodes)
        _check_wide(bvh, wide)
        assert wide.depth < bvh.depth
        assert len(wide.nodes) < 0.25 * len(bvh.nodes)
    # narrower nodes in the same layout: at most `width` lanes used, more nodes
    narrow = collapse(bvh.nodes, width=4)
    _check_wide(bvh, narrow)
    assert np.isfinite(narrow.nodes["lox"]).sum(axis=1).max() == 4
    assert len(narrow.nodes) > len(collapse(bvh.nodes).nodes)
    with pytest.raises(ValueError, match="2 to 8 children"):
        collapse(bvh.nodes, width=9)
    # deterministic: the same bytes again
    bvh = build_bvh(lo, hi, quality="sah")
    assert collapse(bvh.nodes).nodes.tobytes() == collapse(bvh.nodes).nodes.tobytes()
    # a lone leaf: one node with one lane
    one = build_bvh(lo[:3], hi[:3], quality="sah")
    wide = collapse(one.nodes)
    _check_wide(one, wide)
    assert len(wide.nodes) == 1 and np.isfinite(wide.nodes["lox"][0]).sum() == 1


def test_collapse_offsets_and_leaf_limits(rng):
    c = rng.random((300, 3))
    bvh = build_bvh(c, c + 0.01, quality="sah")
    base, moved = collapse(bvh.nodes), collapse(bvh.nodes, node_offset=100, tri_offset=5000)
    inner = base.nodes["child"] >= 0
    leaf = ~inner & np.isfinite(base.nodes["lox"])  # unused lanes have no run
    assert np.array_equal(moved.nodes["child"][inner], base.nodes["child"][inner] + 100)
    run, run_moved = ~base.nodes["child"][leaf], ~moved.nodes["child"][leaf]
    assert np.array_equal(run_moved >> 3, (run >> 3) + 5000) and np.array_equal(run_moved & 7, run & 7)
    big = build_bvh(c, c + 0.01, leaf_size=MAX_LEAF + 1, quality="sah")
    with pytest.raises(ValueError, match="at most 8 triangles"):
        collapse(big.nodes)


def test_stack_fits_and_mirrors_the_kernel(bunny, sponza, cornell):
    """bvh_wide.WIDE_STACK is the kernels' BVH_WIDE_STACK, and the trees of
    the test scenes fit it with room to spare."""
    src = (kernel_dir() / "bvh.h").read_text()
    m = re.search(r"#define BVH_WIDE_STACK \((\d+) \* OCLGI_BVH_STACK_SIZE\)", src)
    assert m and int(m.group(1)) * BVH_STACK_SIZE == WIDE_STACK
    for engine in (bunny, sponza, cornell):
        assert 0 < engine.compiled.bvh_stack_need <= WIDE_STACK // 2 + WIDE


def test_tree_is_selectable_and_fingerprinted(cornell):
    wide, binary = cornell.compiled, binary_of(cornell)
    assert (wide.bvh_quality, wide.bvh_wide, binary.bvh_wide) == ("sah8b", True, False)
    assert wide.n_nodes < binary.n_nodes == binary.n_binary_nodes == wide.n_binary_nodes
    assert not oclgi.Engine(cornell.scene, bvh="lbvh").compiled.bvh_wide
    # the instances' roots say the layout; the fingerprint hashes the traversed nodes
    assert (wide.instances_host["root"] < 0).all() and (binary.instances_host["root"] >= 0).all()
    assert wide.fingerprint() != binary.fingerprint()
    again = CompiledScene(cornell.ctx, cornell.scene)
    assert wide.fingerprint() == again.fingerprint()
    again._leaf_blocks = again._leaf_blocks.copy()
    again._leaf_blocks["v0x"][0, 0] += 1.0
    assert wide.fingerprint() != again.fingerprint()  # the leaf blocks are hashed too
