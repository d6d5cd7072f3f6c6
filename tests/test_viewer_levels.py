"""The viewer's levels of detail (oclgi/viewer/level_of_detail.py) and its
bake of the current pose: each level's rule against a brute-force
clustering in float64, its frames through the socket equal to the
averaging of the API's colours at the pose bit for bit (to float16), the
tessellation's exact colours again when the page asks for them, smaller
frames during a drag; the bake's glTF holds the posed mesh and the API's
radiance."""

import io
import json
import struct
from collections import defaultdict

import numpy as np
import pytest

from viewer_client import connect, open_viewer, receive_until, reference_colours, run_pages, sync


@pytest.fixture(scope="module")
def viewer(scenes_dir):
    v = open_viewer(scenes_dir / "cornell_bunny.toml")
    yield v
    v.executor.shutdown(wait=True)


def bunny_at(dx, dz):
    return [1, 0, 0, dx, 0, 1, 0, 0, 0, 0, 1, dz, 0, 0, 0, 1]


def brute_force(vertices, normals, faces, objects, cell):
    """The module's rule by dictionaries: clusters keyed by (object, cell, normal's direction), their
    area-weighted mean colour's weights and their faces, in float64."""
    lo = vertices.min(axis=0)
    area = np.zeros(len(vertices))
    for f in faces:
        p = vertices[f]
        area[f] += 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])) / 3
    key = {}
    for v in range(len(vertices)):
        axis = int(np.argmax(np.abs(normals[v])))
        key[v] = (int(objects[v]), *np.floor((vertices[v] - lo) / cell).astype(int).tolist(),
                  2 * axis + int(normals[v, axis] < 0))
    triples, faces_out = set(), []
    for f in faces:
        k = tuple(key[int(v)] for v in f)
        if len(set(k)) == 3 and frozenset(k) not in triples:
            triples.add(frozenset(k))
            faces_out.append(k)
    used = {k for f in faces_out for k in f}
    members = defaultdict(list)
    for v, k in key.items():
        if k in used:
            members[k].append(v)
    return members, area, faces_out


def test_a_level_follows_its_rule_against_a_brute_force_clustering():
    """A thin wall (two sides 1 mm apart, facing away from each other), a floor at its foot and a movable
    box overlapping it: the level's clusters, faces and colours equal the dictionary version; no cluster
    mixes objects or the wall's two sides."""
    from oclgi.viewer.level_of_detail import make_level, vertex_areas

    rng = np.random.default_rng(5)

    def grid(origin, u, v, n, normal, obj):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        p = origin + (i.reshape(-1, 1) * u + j.reshape(-1, 1) * v) / n
        quads = [(a * (n + 1) + b, (a + 1) * (n + 1) + b, (a + 1) * (n + 1) + b + 1, a * (n + 1) + b + 1)
                 for a in range(n) for b in range(n)]
        f = np.array([[q[0], q[1], q[2]] for q in quads] + [[q[0], q[2], q[3]] for q in quads])
        return p, np.tile(normal, (len(p), 1)), f, np.full(len(p), obj, np.uint32)

    parts = [grid(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), 12, [0, 1, 0], 0),  # floor
             grid(np.array([0.5, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]), 12, [-1, 0, 0], 0),
             grid(np.array([0.501, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]), 12, [1, 0, 0], 0),
             grid(np.array([0.2, 0.0, 0.2]), np.array([0.3, 0, 0]), np.array([0, 0, 0.3]), 6, [0, 1, 0], 1)]
    vertices, normals, faces, objects, base = [], [], [], [], 0
    for p, n, f, o in parts:
        vertices.append(p + rng.normal(0, 1e-4, p.shape))
        normals.append(n)
        faces.append(f + base)
        objects.append(o)
        base += len(p)
    vertices, normals, faces, objects = map(np.concatenate, (vertices, normals, faces, objects))
    colours = rng.random((len(vertices), 3)).astype(np.float32) * 10
    cell = 0.17
    level = make_level(vertices, normals, faces, objects, vertex_areas(vertices, faces), cell)
    members, area, faces_ref = brute_force(vertices, normals, faces, objects, cell)

    assert len(level.positions) == len(members) and len(level.faces) == len(faces_ref)
    got = level.colours(colours)
    # match the level's clusters to the dictionary's by their mean positions
    index = {}
    for k, vs in members.items():
        mean = vertices[vs].mean(axis=0)
        c = int(np.argmin(np.linalg.norm(level.positions - mean, axis=1)))
        assert np.allclose(level.positions[c], mean, atol=1e-6) and c not in index.values()
        index[k] = c
        assert level.objects[c] == k[0]
        w = area[vs] if area[vs].sum() > 0 else np.ones(len(vs))
        want = (w[:, None] * colours[vs].astype(np.float64)).sum(axis=0) / w.sum()
        assert np.allclose(got[c], want, rtol=1e-6, atol=0), k  # float64 sums in another order, to float32
    assert {tuple(sorted(index[k] for k in f)) for f in faces_ref} == {tuple(sorted(f)) for f in level.faces.tolist()}
    # the wall's sides (direction 0: -x, 1: +x) never share a cluster, nor the box and the floor
    for k, vs in members.items():
        assert len({int(np.argmax(np.abs(normals[v]))) * 2 + int(normals[v, np.argmax(np.abs(normals[v]))] < 0)
                    for v in vs}) == 1
        assert len({int(objects[v]) for v in vs}) == 1


def test_the_default_levels_shrink_by_four_and_load_as_sent(viewer):
    from oclgi.viewer.level_of_detail import FACES_STEP, TOLERANCE, levels_bytes

    faces = len(viewer.tess.faces)
    assert viewer.levels, "the test mesh has levels"
    for k, level in enumerate(viewer.levels, 1):
        target = faces / FACES_STEP ** k
        assert abs(len(level.faces) - target) <= TOLERANCE * target, (k, len(level.faces), target)
        f = level.faces
        assert (f[:, 0] != f[:, 1]).all() and (f[:, 1] != f[:, 2]).all() and (f[:, 0] != f[:, 2]).all()
        assert f.max() < len(level.positions)
    data = levels_bytes(viewer.levels)
    magic, n = struct.unpack_from("<4sI", data)
    assert magic == b"OGVL" and n == len(viewer.levels)
    at = 8
    for level in viewer.levels:
        c, g, h, _ = struct.unpack_from("<IIfI", data, at)
        assert (c, g) == (len(level.positions), len(level.faces)) and np.isclose(h, level.cell)
        assert np.array_equal(np.frombuffer(data, "<u4", 3 * g, at + 16 + 16 * c).reshape(-1, 3), level.faces)
        at += 16 + 16 * c + 12 * g
    assert at == len(data)


def test_level_frames_equal_the_averaging_of_the_api_colours_and_the_full_mesh_returns(viewer):
    async def test(client):
        ws, page, _ = await connect(client, viewer)
        assert page.frame_levels == [0]
        await ws.send_str(json.dumps({"type": "level", "level": 1}))
        await sync(ws, page, 1)
        home = reference_colours(viewer, {})
        assert page.frame_levels[-1] == 1 and page.shows_level(1, viewer.levels[0].colours(home))
        level_sizes = []
        for i, (dx, dz) in enumerate([(0.2, 0.0), (0.3, -0.1), (0.4, -0.2)]):
            n = len(page.sizes)
            await ws.send_str(json.dumps({"type": "move", "object": "bunny", "matrix": bunny_at(dx, dz)}))
            done = await sync(ws, page, 10 + i)
            assert set(page.frame_levels[n:]) == {1}, "a drag at level 1 sent other frames"
            api = reference_colours(viewer, done["poses"])
            assert page.shows_level(1, viewer.levels[0].colours(api))
            assert not page.shows(api)  # the tessellation's colours wait for the page to draw it again
            level_sizes += page.sizes[n:]
        n = len(page.sizes)
        await ws.send_str(json.dumps({"type": "level", "level": 0}))
        done = await sync(ws, page, 20)
        assert page.frame_levels[n:] == [0] and page.seq == done["seq"]
        assert page.shows(reference_colours(viewer, done["poses"]))  # every change of the drag in one frame
        # a level's frames are smaller than the tessellation's would be: the same moves at level 0
        full_sizes = []
        for i, (dx, dz) in enumerate([(0.2, 0.0), (0.3, -0.1), (0.4, -0.2)]):
            n = len(page.sizes)
            await ws.send_str(json.dumps({"type": "move", "object": "bunny", "matrix": bunny_at(dx + 0.01, dz)}))
            await sync(ws, page, 30 + i)
            full_sizes += page.sizes[n:]
        assert sum(level_sizes) < sum(full_sizes) / 2, (level_sizes, full_sizes)
        await ws.close()
    run_pages(viewer, test)


def test_the_bake_is_the_posed_mesh_with_the_api_radiance(viewer):
    import trimesh

    async def test(client):
        ws, page, _ = await connect(client, viewer)
        await ws.send_str(json.dumps({"type": "move", "object": "bunny", "matrix": bunny_at(0.3, -0.2)}))
        done = await sync(ws, page, 1)
        await ws.send_str(json.dumps({"type": "bake", "id": 7, "exposure": 2.0}))
        info = await receive_until(ws, page, lambda m: m["type"] == "baked")
        data = await ws.receive_bytes(timeout=120)
        magic, n = struct.unpack_from("<4sI", data)
        assert magic == b"OGVB" and n == info["bytes"] == len(data) - 8 and info["id"] == 7
        assert info["seq"] == done["seq"]
        await ws.close()
        return data[8:], done

    glb, done = None, None

    async def outer(client):
        nonlocal glb, done
        glb, done = await test(client)
    run_pages(viewer, outer)

    from oclgi.viewer.mesh_payload import vertex_objects

    scene = trimesh.load(io.BytesIO(glb), file_type="glb", process=False)
    api = reference_colours(viewer, done["poses"])
    objects = vertex_objects(viewer.engine.scene, viewer.tess.vertex_tri)[0]
    bunny = scene.geometry["bunny"]
    static = scene.geometry[viewer.engine.scene.objects[0].name]
    on = objects == 1
    shift = np.array(bunny_at(0.3, -0.2)).reshape(4, 4)[:3, 3]
    assert np.allclose(np.sort(bunny.vertices, axis=0), np.sort(viewer.tess.vertices[on] + shift, axis=0), atol=1e-6)
    for geom, mask in ((bunny, on), (static, objects == 0)):
        got = np.asarray(geom.vertex_attributes["_RADIANCE"], np.float32)
        want = api[mask]
        # the mesh keeps its vertices' order within each object
        assert got.shape == want.shape and np.array_equal(got, want)
    colour = np.asarray(static.visual.vertex_colors)[:, :3]
    assert np.array_equal(colour, np.round(np.clip(2.0 * api[objects == 0], 0, 1) * 255))
