"""OpenCL plumbing: device choice, the program cache and shared struct layouts."""
