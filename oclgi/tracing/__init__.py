"""Light tracing: photon paths from the emitters into the path-major segment store."""
