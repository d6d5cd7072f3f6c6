"""Incremental updates equal recomputation, bit for bit (DESIGN.md 4).

After a sequence of random rigid moves (through other geometry, out of the
light, far away and back), a session's accumulators must be identical to a
session built from scratch at the final pose, and moving back to the start
must give the first frame's accumulators again.
"""

import copy
import functools

import numpy as np
import pyopencl as cl
import pytest

import oclgi
import oclgi.estimators
import oclgi.estimators.detp_disc_index as ddi
from analytic_scenes import quad, translation
from oclgi.cl.constants import CELL_OUTSIDE_BIT
from oclgi.incremental.dynamic_view import DynamicView
from oclgi.incremental.segment_store import MAX_CELLS, SegmentStore, grid_dims
from test_instances import _rigid

N_MOVES = 50


def _scene(scenes_dir):
    """The Cornell box with a movable bunny standing on the floor (a copy of
    it read once: the bunny's ASCII PLY takes half a second to parse)."""
    return copy.deepcopy(_read_scene(scenes_dir))


@functools.cache
def _read_scene(scenes_dir):
    return oclgi.load_dict({
        "mesh": [
            {"path": str(scenes_dir / "cornell-box" / "CornellBox-Original.obj")},
            {"path": str(scenes_dir / "stanford-bunny" / "bun_zipper.ply"), "movable": True, "name": "bunny",
             "transform": {"scale": 4.0, "translate": [0.3, -0.13, 0.3]}, "albedo": [0.8, 0.8, 0.8]},
        ],
        "photons": {"count": 20_000, "seed": 21, "max_depth": 10},
    }, base_dir=scenes_dir)


def _moves(rng, n):
    """Random rigid poses: small shifts, big jumps through the boxes and walls,
    one right under the light, one far outside the box."""
    out = []
    for i in range(n):
        m = _rigid(rng, shift=0.8)
        if i % 10 == 3:
            m[:3, 3] = [-0.3, 1.5, -0.3]  # up against the light
        if i % 10 == 7:
            m[:3, 3] = [0, 0, 30.0]  # out of the box, out of the light
        out.append(m)
    return out


def _in_view(rng, n):
    """_moves kept within 0.6 of the origin: in the camera's view, dynamic points every frame."""
    moves = _moves(rng, n)
    for m in moves:
        m[:3, 3] = np.clip(m[:3, 3], -0.6, 0.6)
    return moves


def _camera_engine(scenes_dir, width=24, height=24):
    """The scene seen by the Cornell box's camera."""
    scene = _scene(scenes_dir)
    scene.camera = oclgi.Camera(position=(0, 1, 3.94), look_at=(0, 1, 0), fov=39.3, width=width, height=height)
    return oclgi.Engine(scene)


def _plain_view(session):
    """Plain DETP over a fresh camera pass at the session's pose."""
    at = session.engine
    return at.irradiance(at.camera_points(), method="detp", radius=0.05, photons=10_000)


@pytest.fixture(scope="module")
def engine(scenes_dir):
    return oclgi.Engine(_scene(scenes_dir))


def _points(engine, rng, n=300):
    """Points on the static surfaces of the room, normals into the room."""
    scene = engine.scene
    a, b = scene.object_ranges()[0]
    areas = scene.triangle_areas()[a:b]
    tri = a + rng.choice(b - a, n, p=areas / areas.sum())
    bary = rng.dirichlet([1, 1, 1], n)
    p = np.einsum("rk,rkc->rc", bary, scene.vertices[scene.faces[tri]])
    nrm = scene.triangle_normals()[tri]
    nrm *= np.where(np.einsum("ij,ij->i", nrm, np.array([0, 1, 0]) - p) < 0, -1, 1)[:, None]
    return oclgi.query_points(p, nrm)


INCREMENTAL = [m for m, c in oclgi.estimators.ESTIMATORS.items() if c.incremental]


@pytest.mark.parametrize("method", INCREMENTAL)
def test_incremental_equals_recomputation(engine, rng, method):
    pts = _points(engine, rng)
    engine.move("bunny", np.eye(4))
    session = oclgi.Session(engine, pts, method=method, radius=0.05)
    first = session.accumulators()
    first_segments = session.segments()[0]
    touched = 0
    for m in _moves(rng, N_MOVES):
        touched += session.move("bunny", m).paths
    assert touched > 0
    fresh = oclgi.Session(session.engine, pts, method=method, radius=0.05)  # at the session's pose
    assert np.array_equal(session.accumulators(), fresh.accumulators())
    assert session.segments()[0].tobytes() == fresh.segments()[0].tobytes()
    assert not np.array_equal(session.accumulators(), first)
    # back to the start pose: the first frame again
    session.move("bunny", np.eye(4))
    assert np.array_equal(session.accumulators(), first)
    assert session.segments()[0].tobytes() == first_segments.tobytes()


def test_move_statistics(engine, rng):
    pts = _points(engine, rng, 50)
    engine.move("bunny", np.eye(4))
    session = oclgi.Session(engine, pts, radius=0.05)
    far = translation(0, 0, 30.0)
    segs, _ = session.segments()
    a, b = engine.scene.object_ranges()[1]
    on_bunny = ((segs["tri"] >= a) & (segs["tri"] < b)).reshape(session.params.photons, -1).any(axis=1)
    stats = session.move("bunny", far)  # out of the box: every path that hit it changes
    assert stats.paths >= on_bunny.sum() > 100 and stats.segments_removed > 0
    before = session.accumulators()
    # The same pose again: the only paths re-traced are those that hit the
    # bunny (out there, through the open front), and nothing changes.
    segs, _ = session.segments()
    on_bunny = ((segs["tri"] >= a) & (segs["tri"] < b)).reshape(session.params.photons, -1).any(axis=1)
    again = session.move("bunny", far)
    assert again.paths == on_bunny.sum() and again.segments_removed == again.segments_added
    assert np.array_equal(session.accumulators(), before)
    session.move("bunny", np.eye(4))


@pytest.mark.parametrize("method", INCREMENTAL)
def test_camera_session_equals_recomputation(scenes_dir, rng, method):
    """A camera session: pixels that see the object (or saw it) are dynamic
    points, recomputed; after 20 moves the view equals a fresh session's."""
    session = oclgi.Session(_camera_engine(scenes_dir), method=method, radius=0.05, photons=10_000)
    first_radiance, _ = session.render()
    recomputed = 0
    for m in _moves(rng, 20):
        recomputed += session.move("bunny", m).points
    assert recomputed > 0
    fresh = oclgi.Session(session.engine, method=method, radius=0.05, photons=10_000)
    assert session.points.positions.tobytes() == fresh.points.positions.tobytes()
    assert np.array_equal(session.accumulators(), fresh.accumulators())
    if method.startswith("detp"):  # every DETP variant equals plain DETP over the whole view
        assert np.array_equal(session.accumulators(), _plain_view(session).accumulators)
    assert np.array_equal(session.render()[0], fresh.render()[0])
    session.move("bunny", np.eye(4))
    assert np.array_equal(session.render()[0], first_radiance)


DETP_VARIANTS = [m for m in INCREMENTAL if m.startswith("detp")]


@pytest.mark.parametrize("dynamic", DETP_VARIANTS)
def test_dynamic_points_by_every_variant(scenes_dir, rng, dynamic):
    """The dynamic points (pixels on the bunny) are recomputed by any DETP
    variant; disc indexing sums them in the find pass over the old store
    and corrects them with the changed suffixes, the others sum the new
    store. All equal plain DETP over a fresh full view."""
    engine = _camera_engine(scenes_dir, 32, 32)
    engine.move("bunny", np.eye(4))
    session = oclgi.Session(engine, method="detp_disc_index", dynamic=dynamic, radius=0.05, photons=10_000)
    assert sum(session.move("bunny", m).points for m in _in_view(rng, 8)) > 50
    plain = _plain_view(session)
    assert np.array_equal(session.accumulators(), plain.accumulators)
    np.testing.assert_array_equal(session.irradiance(), plain.irradiance)


@pytest.mark.parametrize("count_emitted", [True, False])
def test_summed_changes_equal_subtract_then_add(scenes_dir, rng, count_emitted):
    """A move's suffixes summed in one pass after the re-trace, the common
    part of each first segment skipped (Session.sum_changes, the default),
    against the plain subtraction and addition passes: the accumulators
    equal after every move, bit for bit, for the static points and the
    dynamic ones (pixels on the bunny, summed in the find pass, whose sums
    the suffix passes then update)."""
    moves = _in_view(rng, 12)
    runs = {}
    for summed in (False, True):
        session = oclgi.Session(_camera_engine(scenes_dir), method="detp_disc_index", radius=0.05, photons=10_000,
                                count_emitted=count_emitted, count_work=True)
        session.sum_changes = summed
        session.dynamic_pass = "find"
        runs[summed] = [(session.move("bunny", m), session.accumulators().copy()) for m in moves]
        runs[summed].append((None, session.work()))
    for i, ((st_a, acc_a), (st_b, acc_b)) in enumerate(zip(runs[False][:-1], runs[True][:-1])):
        assert st_a.paths == st_b.paths and st_a.points == st_b.points
        assert np.array_equal(acc_a, acc_b), f"move {i}: {(acc_a != acc_b).any(axis=-1).sum()} points differ"
    assert sum(st.paths for st, _ in runs[True][:-1]) > 100 and sum(st.points for st, _ in runs[True][:-1]) > 20
    # the skipped common parts: fewer segment-disc tests in all
    assert runs[True][-1][1]["u"] < runs[False][-1][1]["u"], (runs[True][-1][1], runs[False][-1][1])


def test_listed_crossings_equal_walks(engine, rng, monkeypatch):
    """A session's static points sum a re-traced path's old suffix from the
    discs its segments crossed when the last move added them
    (DetpDiscIndex.list_crossings): over small steps, where most paths are
    re-traced again, the accumulators equal walking every segment, bit for
    bit, after every move; lists that overflow are left out; after a move
    with the plain passes (no lists made) the older lists are not used."""
    pts = _points(engine, rng, 2000)
    engine.move("bunny", np.eye(4))
    for per_path in (ddi.LISTED_PER_PATH, 4):
        monkeypatch.setattr(ddi, "LISTED_PER_PATH", per_path)
        listed = oclgi.Session(engine, pts, method="detp_disc_index", photons=100_000, radius=0.05)
        walked = oclgi.Session(engine, pts, method="detp_disc_index", photons=100_000, radius=0.05)
        walked.estimator.list_crossings = False
        assert listed.estimator.list_crossings
        counts = []
        for i in range(10):
            m = translation(0.03 * i - 0.1, 0.0, 0.02 * i)
            plain = i == 5  # one move by the plain passes: its new segments get no lists
            listed.sum_changes = walked.sum_changes = not plain
            a, b = listed.move("bunny", m), walked.move("bunny", m)
            assert a.paths == b.paths and a.paths > 100
            assert np.array_equal(listed.accumulators(), walked.accumulators()), (per_path, i)
            counts.append(listed.estimator.replayed())
        assert walked.estimator.replayed() == 0
        assert counts[1] > 100, counts  # the second move already sums most old suffixes from lists
        assert counts[6] == counts[5], counts  # after the plain move: nothing to replay
        assert counts[9] > counts[6], counts
    engine.move("bunny", np.eye(4))


def test_dynamic_passes_agree(scenes_dir, rng):
    """A camera session's disc-indexed dynamic points summed after the
    update over only the paths whose cell masks meet their discs' box
    (``dynamic_pass = "listed"``, the default), in the find pass ("find")
    and over every stored path ("store"): the same accumulators after every
    move, bit for bit, and plain DETP's at the end. The listed pass tests
    the same discs as the whole store's (a path it leaves out meets none)
    and visits fewer nodes (it leaves those paths' root visits out); its
    index is built while the device re-traces, the paths listed by the
    find in a box around the points, the one scan of the masks a move."""
    moves = _in_view(rng, 10)
    runs, work = {}, {}
    for mode in ("store", "find", "listed"):
        session = oclgi.Session(_camera_engine(scenes_dir), method="detp_disc_index", radius=0.05, photons=10_000,
                                count_work=True)
        session.dynamic_pass = mode
        listings = []
        list_candidates = session.store._list_candidates
        session.store._list_candidates = lambda boxes: listings.append(boxes) or list_candidates(boxes)
        runs[mode] = [(session.move("bunny", m).points, session.accumulators().copy()) for m in moves]
        work[mode] = session.dynamic_work
        # one scan of the masks per move: the find's list, made in a box
        # around the points before their index, holds the index's box
        assert len(listings) == len(moves), (mode, len(listings))
    assert sum(points for points, _ in runs["listed"]) > 20
    for mode in ("find", "listed"):
        for i, ((pa, acc_a), (pb, acc_b)) in enumerate(zip(runs["store"], runs[mode])):
            assert pa == pb
            assert np.array_equal(acc_a, acc_b), f"{mode}, move {i}: {(acc_a != acc_b).any(axis=-1).sum()} differ"
    assert np.array_equal(runs["listed"][-1][1], _plain_view(session).accumulators)
    assert work["listed"]["u"] == work["store"]["u"], work
    assert work["listed"]["nodes"] < work["store"]["nodes"], work


@pytest.mark.parametrize("kwargs, match", [(dict(dynamic="impact"), "dynamic points are recomputed by a DETP variant"),
                                           (dict(method="photon_map"), "no exact incremental update")])
def test_sessions_refuse_what_they_cannot_update_exactly(engine, kwargs, match):
    with pytest.raises(oclgi.OclgiError, match=match):
        oclgi.Session(engine, np.array([[0, 0.01, 0, 0, 1, 0]]), photons=1000, **kwargs)


def test_view_rectangle_holds_every_pixel_on_the_object(scenes_dir, rng):
    """The projected rectangle of the movable object's box must contain every
    pixel that sees the object (else a dynamic point would be missed), also
    when the object is close to the eye or partly behind it; the composite
    view then equals a full camera pass bit for bit."""
    engine = _camera_engine(scenes_dir, 96, 80)
    scene = engine.scene
    view = DynamicView(engine)
    seen = 0
    for i in range(40):
        m = _rigid(rng, shift=0.9)
        if i % 8 == 5:
            m[:3, 3] = [0.0, 1.0, 3.7]  # around the eye: the box reaches behind it
        engine.move("bunny", m)
        x0, y0, w, h = view.rectangle()
        full = engine.camera_points()
        on = np.nonzero(view.on_movable(full.tri))[0]
        ys, xs = np.divmod(on, scene.camera.width)
        assert ((xs >= x0) & (xs < x0 + w) & (ys >= y0) & (ys < y0 + h)).all()
        seen += len(on)
        view.update()
        assert view.points.positions.tobytes() == full.positions.tobytes()
        assert view.points.normals.tobytes() == full.normals.tobytes()
        assert np.array_equal(np.sort(view.dynamic), on)
        if 0 < w * h < scene.camera.width * scene.camera.height:
            assert len(on) < w * h  # a real rectangle, not always the whole image
    assert seen > 1000
    engine.move("bunny", np.eye(4))


def test_cell_masks_find_what_a_full_scan_finds(engine, rng):
    """The find examines only paths whose cell mask meets the object's old
    and new boxes: over random moves (kept up to date by re-tracing) it must
    list exactly the paths and first bounces a scan of every path lists."""
    engine.move("bunny", np.eye(4))
    masked, full = (SegmentStore(engine, 20_000, 5, 10) for _ in range(2))
    full._region = lambda boxes: None  # every path, every move
    obj = engine.scene.object_id("bunny")
    filtered = 0
    for m in _moves(rng, 30):
        engine.move("bunny", m)
        a, b = masked.find(obj), full.find(obj)
        assert np.array_equal(a.paths, b.paths) and np.array_equal(a.starts, b.starts)
        filtered += masked.examined < full.examined
        if len(a):
            masked.retrace(a)
            full.retrace(b)
    assert filtered >= 20  # the masks did the work on most moves (not the moves out of the box)
    assert masked.segments().tobytes() == full.segments().tobytes()
    engine.move("bunny", np.eye(4))


def test_a_box_past_one_face_lists_only_the_paths_leaving_through_it(engine):
    """A box out of the grid below the Cornell box's floor, or behind its
    back wall, examines beside the old box's paths only those that leave
    the grid through that face (none: the box is closed but for its front),
    not every path that leaves it: a mask has a bit per face, set for the
    faces its segments leave and enter by. Most of the paths that leave by
    the open front go on downwards, below the floor's plane, outside: a
    bit for every face a segment's box reaches past would list them. The
    find still equals a full scan."""
    engine.move("bunny", np.eye(4))
    seg = None
    for shift in ([0.0, -30.0, 0.0], [0.0, 0.0, -30.0]):
        masked, full = (SegmentStore(engine, 20_000, 5, 10) for _ in range(2))
        full._region = lambda boxes: None
        obj = engine.scene.object_id("bunny")
        n_old = masked._list_candidates([masked.boxes[obj]])[1]
        if seg is None:
            seg = masked.segments().reshape(masked.photons, masked.max_depth)
            escaping = (seg["t_end"] == np.inf) & (np.abs(seg["dir"]).sum(axis=2) > 0)
            down = (escaping & (seg["dir"][:, :, 1] < 0)).any(axis=1).sum()
            assert down > 2000  # leave by the front, going down
        engine.move("bunny", translation(*shift))
        a, b = masked.find(obj), full.find(obj)
        assert np.array_equal(a.paths, b.paths) and np.array_equal(a.starts, b.starts)
        assert masked.examined <= n_old + 20, (shift, masked.examined, n_old)
        engine.move("bunny", np.eye(4))


def _reference_faces(o, w, t_end, lo, hi, g0, g1) -> np.ndarray:
    """kernels/update.cl cell_faces in numpy float32, segment by segment."""
    f32 = np.float32
    inv = f32(1.0) / w
    box = np.zeros(len(o), np.uint64)
    for a in range(3):
        box |= (lo[:, a] < g0[a]).astype(np.uint64) << np.uint64(2 * a)
        box |= (hi[:, a] > g1[a]).astype(np.uint64) << np.uint64(2 * a + 1)
    t0, t1 = (g0[None] - o) * inv, (g1[None] - o) * inv
    tin, tout = np.fmin(t0, t1), np.fmax(t0, t1)
    t_in = np.fmax(np.fmax(tin[:, 0], tin[:, 1]), tin[:, 2])
    t_out = np.fmin(np.fmin(tout[:, 0], tout[:, 1]), tout[:, 2])
    through = (t_in <= t_out) & (t_out >= 0) & (t_in <= t_end)
    up = inv > 0
    crossed = np.zeros(len(o), np.uint64)
    leaves = t_out <= t_end + t_end * f32(1e-5)
    enters = (o < g0[None]).any(axis=1) | (o > g1[None]).any(axis=1)
    for a in range(3):
        by_out = leaves & (tout[:, a] <= t_out + np.abs(t_out) * f32(1e-5))
        crossed |= by_out.astype(np.uint64) << (2 * a + up[:, a]).astype(np.uint64)
        by_in = enters & (tin[:, a] >= t_in - np.abs(t_in) * f32(1e-5))
        crossed |= by_in.astype(np.uint64) << (2 * a + 1 - up[:, a]).astype(np.uint64)
    return np.where(box == 0, np.uint64(0), np.where(through, crossed, box))


def _reference_cells(store) -> np.ndarray:
    """Each path's cell mask (two uint64), in numpy float32 with the
    kernel's operations in its order (kernels/update.cl update_path_cells):
    box_slab on every padded cell within the segment's box, one cell at a
    time (the slow, obvious form of the kernel's 8 columns at once)."""
    f32 = np.float32
    seg = store.segments().reshape(store.photons, store.max_depth)
    plen = store.path_len()
    valid = np.arange(store.max_depth)[None] < plen[:, None]
    path = np.nonzero(valid)[0]
    s = seg[valid]
    o, w, t = s["org"], s["dir"], s["t_end"]
    g, cell, pad = store.grid_lo.astype(f32), store.cell.astype(f32), f32(store.pad)
    dims = store.dims.astype(np.int64)
    top = dims - 1
    escape = t == np.inf
    with np.errstate(all="ignore"):
        e = o + t[:, None] * w
        lo, hi = np.fmin(o, e), np.fmax(o, e)
        c0 = np.clip(np.floor((lo - pad - g) / cell), 0, top).astype(np.int64)
        c1 = np.clip(np.floor((hi + pad - g) / cell), 0, top).astype(np.int64)
        c0[escape], c1[escape] = 0, top
        g1 = g + dims.astype(f32) * cell - pad
        # an escaping segment's box reaches infinity along its direction
        lo = np.where(escape[:, None], np.where(w < 0, -np.inf, o), lo)
        hi = np.where(escape[:, None], np.where(w > 0, np.inf, o), hi)
        faces = _reference_faces(o, w, t, lo, hi, g + pad, g1)
        inv = f32(1.0) / w
        slab = []
        for a in range(3):
            ks = np.arange(dims[a])
            lo_a = g[a] + ks.astype(f32) * cell[a] - pad  # (cells,)
            t0 = (lo_a[None] - o[:, a:a + 1]) * inv[:, a:a + 1]
            t1 = (lo_a[None] + cell[a] + f32(2.0) * pad - o[:, a:a + 1]) * inv[:, a:a + 1]
            slab.append((np.fmin(t0, t1), np.fmax(t0, t1)))
        bits = np.zeros((len(s), 2), np.uint64)
        for z in range(dims[2]):
            nz = np.fmax(slab[2][0][:, z], f32(0.0))
            fz = np.fmin(slab[2][1][:, z], t)
            for y in range(dims[1]):
                ny, fy = np.fmax(slab[1][0][:, y], nz), np.fmin(slab[1][1][:, y], fz)
                for x in range(dims[0]):
                    met = np.fmax(slab[0][0][:, x], ny) <= np.fmin(slab[0][1][:, x], fy) * f32(1.0000004)
                    cube = np.array([x, y, z])
                    met &= ((c0 <= cube) & (cube <= c1)).all(axis=1)
                    c = x + dims[0] * (y + dims[1] * z)
                    bits[met, c >> 6] |= np.uint64(1 << (c & 63))
    bits[:, 1] |= faces << np.uint64(CELL_OUTSIDE_BIT - 64)
    masks = np.zeros((store.photons, 2), np.uint64)
    np.bitwise_or.at(masks, path, bits)
    return masks


def _cells(store) -> np.ndarray:
    """The store's cell masks, read from the device."""
    got = np.empty((store.photons, 2), np.uint64)
    cl.enqueue_copy(store.queue, got, store.cells)
    return got


def test_cell_masks_equal_a_cell_by_cell_reference(engine):
    """The kernel's masks (8 columns at a time) equal a float32 reference
    that tests each cell alone, bit for bit, after the trace and after
    re-traces (the re-traced paths' masks are made again)."""
    engine.move("bunny", np.eye(4))
    store = SegmentStore(engine, 4_000, 9, 10)
    obj = engine.scene.object_id("bunny")
    for m in [None] + _moves(np.random.default_rng(5), 4):
        if m is not None:
            engine.move("bunny", m)
            a = store.find(obj)
            if len(a):
                store.retrace(a)
        got, want = _cells(store), _reference_cells(store)
        assert np.array_equal(got, want), f"{int((got != want).any(axis=1).sum())} paths differ"
        assert (got[:, 0] != 0).sum() > store.photons // 2  # cells were marked, not only the outside bit
    # rows of more than 8 columns (two float8 runs) and of 1 (a long scene's grids)
    extent = store.dims * store.cell
    for dims in ([15, 4, 2], [122, 1, 1], [1, 1, 122]):
        store.dims = np.array(dims)
        store.cell = extent / store.dims
        store._mark_cells(store.all_paths, store.photons)
        assert np.array_equal(_cells(store), _reference_cells(store)), dims
    engine.move("bunny", np.eye(4))
    # under a sun, whose paths start outside the grid and enter it from above
    sunlit = oclgi.Engine(oclgi.load_dict({"mesh": [quad(0.0, 3.0, 0.7, name="ground", movable=False),
                                                    quad(0.5, 0.5, 0.7, name="roof", movable=True)],
                                           "sun": {"direction": [0.3, -1.0, 0.2], "irradiance": [1.0] * 3},
                                           "photons": {"count": 4_000, "seed": 2, "max_depth": 4}}))
    store = SegmentStore(sunlit, 4_000, 2, 4)
    got = _cells(store)
    assert np.array_equal(got, _reference_cells(store))
    faces = (got[:, 1] >> np.uint64(CELL_OUTSIDE_BIT - 64)) & np.uint64(63)
    assert (faces != 0).all()  # every sun path starts outside the grid
    top = (faces & np.uint64(8)) != 0
    assert top.sum() > len(faces) // 2 and (faces == 8).sum() > 100  # most enter by the top, some only so


def test_grid_dims_fit_the_mask_and_follow_the_scene():
    for extent, expect in (([2, 2, 2], [5, 5, 4]), ([35.5, 17.4, 16.3], [7, 4, 4]), ([1, 1, 0], [11, 11, 1]),
                           ([1e6, 1, 1], [122, 1, 1])):
        dims = grid_dims(extent)
        assert dims.tolist() == expect and np.prod(dims) <= MAX_CELLS
