"""A page's large render in a process of its own, so that other pages never wait for it.

The server's device calls share one worker thread (oclgi/viewer/connection.py),
and PoCL runs one process's kernels in the order they were queued, whatever
their queue: a render's camera pass over 4096 x 4096 pixels, its disc index
over as many points and its batches would each hold every other page's
move for seconds (a move + sync took 4.3 to 36 s during such a render on
2 cores). A kernel of another process is scheduled by the operating system
beside the server's instead: the pages' moves then share the cores with
the render rather than queue behind it, and a page that goes away stops
its render at once (the process is killed; nothing of it is left).

The process renders what the page's render in the server would: a new
engine over the same scene, device, work-group size and tree, its objects
placed at the session's poses and its lights at the page's, and
``Engine.render_run`` from the page's camera with the session's run
parameters; the image is the same bit for bit (tests/test_viewer_socket.py).
Small renders stay in the server's process (IN_PROCESS_PIXELS): a process
costs about a second to start, and their steps are short. A render takes
``oclgi render``'s default estimate (oclgi/estimators/render_preset.py:
several samples a pixel with exact direct light, the indirect light
gathered) unless the page asks for the photons' estimate alone; its last
step (the direct light and the gather of every sample) is one call of
seconds past IN_PROCESS_GATHERED pixels, so such a render runs in a
process of its own too.
"""

from __future__ import annotations

import asyncio
import multiprocessing
import signal
import time

from ..errors import OclgiError

IN_PROCESS_PIXELS = 512 * 512  # at most this many pixels render in the server's own process
IN_PROCESS_GATHERED = 64 * 64  # likewise with the default estimate (its last step is one call)
PROGRESS_SECONDS = 0.1  # at most ten progress messages a second


def render_args(params, options: dict, width: int, height: int, plain: bool) -> dict:
    """``Engine.render_run``'s arguments for a page's render with a
    session's run parameters and options: its method, photons, seed,
    depth and radius (or k), and unless ``plain`` the command's default
    samples and options for a DETP method (``spp`` among them)."""
    from ..estimators import ESTIMATORS
    from ..estimators.render_preset import render_settings

    args = dict(method=params.method, photons=params.photons, seed=params.seed, max_depth=params.max_depth)
    if params.method == "photon_map":
        args["k"] = options["k"]
    else:
        args["radius"] = params.radius
    if not plain:
        args.update(render_settings(ESTIMATORS[params.method].family, {"count_emitted": params.count_emitted},
                                    False, width, height))
    return args


def elsewhere(width: int, height: int, args: dict) -> bool:
    """Does a render of these arguments (render_args) run in a process of its own?"""
    pixels = width * height
    return pixels > IN_PROCESS_PIXELS or ("gather" in args and pixels > IN_PROCESS_GATHERED)


def job_of(engine, poses: dict, lights: dict, camera, args: dict, batch: int) -> dict:
    """What the process needs (picklable): the scene, how the engine was
    made, the poses (name -> 4x4), light changes, the camera and the run's
    arguments."""
    return {"scene": engine.scene, "device": engine.device_spec, "local_size": engine.local_size,
            "bvh": engine.compiled.bvh_quality, "poses": poses, "lights": dict(lights), "camera": camera,
            "args": args, "batch": batch}


def _render(pipe, job: dict) -> None:
    """The process: render ``job``, sending ("progress", traced, paths,
    stage) now and then and once before the last step (stage "photons",
    then "final": Connection._progress), and at last ("done", radiance,
    pixels) or ("error", text)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C stops the server, which stops this
    try:
        from ..engine import Engine

        engine = Engine(job["scene"], device=job["device"], local_size=job["local_size"], bvh=job["bvh"])
        for name, matrix in job["poses"].items():
            engine.place(name, matrix)
        if job["lights"]:
            engine._apply_parameters(job["lights"])
        run = engine.render_run(job["camera"], **job["args"])
        run.set_batch(min(run.batch, job["batch"]))
        last = 0.0
        while not run.done:
            run.step()
            if time.monotonic() - last >= PROGRESS_SECONDS:
                last = time.monotonic()
                pipe.send(("progress", int(run.traced), int(run.paths.count), "photons"))
        pipe.send(("progress", int(run.traced), int(run.paths.count), "final"))
        image = engine.render_result(run, run.finish())
        pipe.send(("done", image.radiance, image.pixels))
    except OclgiError as exc:
        pipe.send(("error", str(exc)))
    except MemoryError:
        pipe.send(("error", "the render ran out of memory: ask for a smaller image or fewer photons"))
    except Exception as exc:  # the page gets one line; the server goes on
        pipe.send(("error", f"the render failed: {type(exc).__name__}: {exc}"))


class RenderProcess:
    """One render in a spawned process (never forked: the server's OpenCL
    runtime and threads do not survive a fork)."""

    def __init__(self, job: dict):
        ctx = multiprocessing.get_context("spawn")
        self.pipe, child = ctx.Pipe(duplex=False)
        self.process = ctx.Process(target=_render, args=(child, job), daemon=True, name="oclgi-render")
        self.process.start()
        child.close()

    async def receive(self, still_wanted):
        """The process's next message, or None when it ended without one
        or ``still_wanted()`` turned false while waiting."""
        loop = asyncio.get_running_loop()
        while still_wanted():
            ready = await loop.run_in_executor(None, self.pipe.poll, PROGRESS_SECONDS)
            if ready:
                try:
                    return await loop.run_in_executor(None, self.pipe.recv)
                except EOFError:
                    return None
            if not self.process.is_alive() and not self.pipe.poll():
                return None
        return None

    def stop(self) -> None:
        """Kill the process (if it still runs) and wait for it: nothing of it is left."""
        if self.process.is_alive():
            self.process.kill()
        self.process.join()
        self.pipe.close()
