"""``oclgi view``: interactive global illumination in the browser (oclgi/viewer/server.py)."""
