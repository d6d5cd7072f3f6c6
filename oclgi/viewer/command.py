"""The ``oclgi view`` command: load, tessellate, serve until Ctrl-C."""

from __future__ import annotations

import asyncio
import sys
import time

from ..errors import OclgiError


def view(args) -> None:
    try:
        import aiohttp  # noqa: F401
    except ImportError:
        raise OclgiError("oclgi view needs aiohttp: pip install 'oclgi[viewer]'") from None
    from ..engine import Engine
    from ..scene.description import load_file
    from ..scene.tessellate import tessellate
    from .guard import check_origins
    from .server import Viewer

    from .ledger import parse_size

    origins = check_origins(args.allow_origin)  # before any work
    memory = parse_size(args.memory) if args.memory is not None else None
    t0 = time.perf_counter()
    scene = load_file(args.scene)
    engine = Engine(scene, device=args.device, local_size=args.local_size, progress=False)
    run = engine.run_params(args.method, args.photons, args.radius)
    tess = tessellate(scene, args.edge if args.edge is not None else run.radius)
    viewer = Viewer(engine, tess, args.method, args.photons, args.radius, args.all_vertices, allow_origins=origins,
                    memory=memory, max_pages=args.max_pages)
    if not args.quiet:
        print(f"oclgi view: {scene.name}: {len(tess.vertices):,} vertices (edge {tess.edge:.3g}), "
              f"{len(viewer.points):,} query points, "
              f"{run.photons:,} photons per page, {run.method}; ready in {time.perf_counter() - t0:.1f}s",
              file=sys.stderr)

    def ready(url: str) -> None:
        print(url, flush=True)
        if not args.quiet:
            print("oclgi view: open the URL in a browser; Ctrl-C stops the server", file=sys.stderr, flush=True)

    asyncio.run(viewer.serve(args.host, args.port, ready))
