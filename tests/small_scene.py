"""A tiny scene shared by the command-line tests: a floor quad and a small
quad light above it, facing down (materials `floor` and `light`)."""

BOX_OBJ = """mtllib box.mtl
v -1 0 -1
v 1 0 -1
v 1 0 1
v -1 0 1
v -0.2 1 -0.2
v 0.2 1 -0.2
v 0.2 1 0.2
v -0.2 1 0.2
usemtl floor
f 1 4 3 2
usemtl light
f 5 6 7 8
"""
BOX_MTL = "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl light\nKd 0 0 0\nKe 5 5 5\n"
SCENE = """[[mesh]]
path = "{mesh}"
{mesh_keys}
[camera]
position = [0, 0.5, 3]
look_at = [0, 0.3, 0]
width = 8
height = 8

[photons]
count = {count}
{photon_keys}
[estimator]
radius = {radius}
"""
POINTS = "x,y,z,nx,ny,nz\n0,0.01,0,0,1,0\n0.5,0.01,0.5,0,1,0\n"


def write_scene(d, obj=BOX_OBJ, mtl=BOX_MTL, mesh="box.obj", mesh_keys="", count="2000", radius="0.1", extra="",
                name="s.toml", photon_keys="", scene=None):
    """The scene file ``name`` in folder ``d`` (made if need be): ``scene``, or
    SCENE with these values and ``extra``; with box.obj, box.mtl (None: left
    out) and the points file p.csv beside it."""
    d.mkdir(parents=True, exist_ok=True)
    if scene is None:
        scene = SCENE.format(mesh=mesh, mesh_keys=mesh_keys, count=count, photon_keys=photon_keys,
                             radius=radius) + extra
    for file, text in (("box.obj", obj), ("box.mtl", mtl), ("p.csv", POINTS), (name, scene)):
        if text is not None:
            (d / file).write_text(text)
    return d / name


# A floor and a movable block under a point light, with a camera: the
# smallest scene `animate` runs on.
MOVING_BLOCK = """[[mesh]]
vertices = [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]
faces = [[0, 2, 1], [0, 3, 2]]

[[mesh]]
name = "block"
movable = true
vertices = [[-0.1, 0, -0.1], [0.1, 0, -0.1], [0.1, 0.2, 0.1], [-0.1, 0.2, 0.1]]
faces = [[0, 1, 2], [0, 2, 3]]

[[point_light]]
position = [0, 1, 0]
intensity = [1, 1, 1]

[camera]
position = [0, 1, 2]
look_at = [0, 0, 0]
width = 8
height = 8

[photons]
count = 2000
"""
