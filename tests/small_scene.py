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
