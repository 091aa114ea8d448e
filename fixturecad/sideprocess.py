"""A side process: pictures and register.py, off the critical path, on the second core.

A command that will draw (``build``'s preview.png, ``calibrate``'s
calibration.png) starts ``python -m fixturecad.sideprocess`` first. The child
imports matplotlib and the register.py generator (which pulls in scipy) while
the parent does its own work (importing the CAD kernel, fitting); then the
parent sends the jobs, by name, with their arguments.
"""

import importlib
import pickle
import re
import subprocess
import sys

# The jobs a parent may send: name -> (module, function).
JOBS = {
    "preview": ("fixturecad.preview", "render"),
    "register": ("fixturecad.registration.generate", "write_register_script"),
    "calibration": ("fixturecad.calibration_plot", "plot_calibration"),
}


class SideProcess:
    """Parent end: start now naming the jobs to come, ``send`` them later, ``wait`` for them."""

    def __init__(self, *names):
        unknown = [name for name in names if name not in JOBS]
        if unknown:
            raise ValueError(f"unknown side job {unknown[0]!r}; jobs are {', '.join(JOBS)}")
        self.names = names
        self.process = subprocess.Popen(
            [sys.executable, "-m", "fixturecad.sideprocess", *names], stdin=subprocess.PIPE, stderr=subprocess.PIPE
        )

    def send(self, *jobs) -> None:
        """Run ``(name, *arguments)`` jobs in the child, in order (names given at the start); jobs sent
        later run after these."""
        for job in jobs:
            if job[0] not in self.names:
                raise ValueError(f"side job {job[0]!r} was not named at the start")
        self.process.stdin.write(pickle.dumps(jobs))
        self.process.stdin.flush()

    def wait(self) -> None:
        """Wait for the child to finish the jobs sent; if it failed, its OSError (a full disk) as the caller's
        own, else RuntimeError with its last error line."""
        self.process.stdin.close()
        error = self.process.stderr.read()
        self.process.wait()
        if self.process.returncode != 0:
            lines = error.decode(errors="replace").strip().splitlines()
            failed = re.search(r"\[Errno (\d+)\] ([^:]+)", lines[-1]) if lines else None
            if failed:
                raise OSError(int(failed[1]), failed[2])
            raise RuntimeError(f"side process failed: {lines[-1] if lines else 'no message'}")

    def cancel(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.process.stderr.close()


def _warm(names) -> None:
    """Import what the named jobs need; for a preview, a throw-away 3D drawing loads fonts and mplot3d."""
    for name in names:
        importlib.import_module(JOBS[name][0])
    if "preview" in names:
        import io

        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        figure = Figure(figsize=(1, 1), dpi=20)
        FigureCanvasAgg(figure)
        axes = figure.add_subplot(projection="3d")
        axes.text(0, 0, 0, "x", fontweight="bold")
        axes.set_xlabel("x")
        figure.savefig(io.BytesIO(), format="png")


def _main() -> None:
    _warm(sys.argv[1:])
    while True:
        try:
            jobs = pickle.load(sys.stdin.buffer)
        except EOFError:
            return  # the parent is done, or gave up
        for name, *arguments in jobs:
            module, function = JOBS[name]
            getattr(importlib.import_module(module), function)(*arguments)


if __name__ == "__main__":
    _main()
