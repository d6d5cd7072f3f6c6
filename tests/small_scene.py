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
