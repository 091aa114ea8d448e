"""The build's side process: preview.png and register.py, off the CAD critical path.

``fixturecad build`` starts ``python -m fixturecad.sideprocess`` before it
imports cadquery. The child imports matplotlib (and the register.py
generator, which pulls in scipy) on the second core while the parent imports
the CAD kernel and builds the solid; then the parent sends one job: a pickled
preview scene and, once features.json is written, where register.py goes.
"""

import json
import pickle
import subprocess
import sys
from pathlib import Path


class SideProcess:
    """Parent end: start now, ``send`` the job later, ``wait`` for the files."""

    def __init__(self, folder):
        self.folder = Path(folder)
        self.process = subprocess.Popen(
            [sys.executable, "-m", "fixturecad.sideprocess"], stdin=subprocess.PIPE, stderr=subprocess.PIPE
        )

    def send(self, scene: dict, preview: Path, features: Path, register: Path) -> None:
        """Draw ``scene`` into ``preview``; write ``register`` from the features.json at ``features``."""
        scene_path = self.folder / ".scene.pickle"
        scene_path.write_bytes(pickle.dumps(scene))
        job = {"scene": str(scene_path), "preview": str(preview), "features": str(features), "register": str(register)}
        self.process.stdin.write(json.dumps(job).encode() + b"\n")
        self.process.stdin.close()

    def wait(self) -> None:
        """Wait for the child; RuntimeError with its last error line if it failed."""
        error = self.process.stderr.read()
        self.process.wait()
        if self.process.returncode != 0:
            lines = error.decode(errors="replace").strip().splitlines()
            raise RuntimeError(f"preview or register.py failed: {lines[-1] if lines else 'no message'}")

    def cancel(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.process.stderr.close()


def _warm_imports() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    # a throw-away drawing loads fonts and the 3D machinery while the parent is busy
    figure = Figure(figsize=(1, 1), dpi=20)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot(projection="3d")
    axes.text(0, 0, 0, "x", fontweight="bold")
    axes.set_xlabel("x")
    figure.savefig(io.BytesIO(), format="png")

    import fixturecad.registration.generate  # noqa: F401  (warm: it pulls in scipy)


def _main() -> None:
    _warm_imports()
    line = sys.stdin.readline()
    if not line.strip():
        return  # the parent gave up
    job = json.loads(line)
    from fixturecad.preview import render
    from fixturecad.registration.generate import write_register_script

    scene_path = Path(job["scene"])
    scene = pickle.loads(scene_path.read_bytes())
    scene_path.unlink()
    render(scene, job["preview"])
    document = json.loads(Path(job["features"]).read_text(encoding="utf-8"))
    write_register_script(document, Path(job["register"]))


if __name__ == "__main__":
    _main()
