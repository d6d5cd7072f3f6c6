"""OpenCL C sources of oclgi (installed as package data: *.cl and *.h)."""
