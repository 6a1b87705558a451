"""The figures of docs/opendrive.md about maps that come without one (`make docs`): a map built
from the trajectories of a simulated network with a lane drop and a four-way junction, drawn with
the trajectories over it and the residuals per lane, and the same against netconvert's own
OpenDRIVE of the network."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main(out: Path) -> list[Path]:
    sys.path.insert(0, str(ROOT / "tests"))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from helpers_mapbuild import sumo_scene

    from aveas_format.opendrive import load_map
    from aveas_format.opendrive.roadfit.tracks import map_from_tracks
    from aveas_format.plot.map import plot_map
    from aveas_format.plot.mapbuild import save_build

    with tempfile.TemporaryDirectory() as tmp:
        sc = sumo_scene(Path(tmp))
        built = map_from_tracks(sc.x, sc.y, sc.track, sc.time, heading=sc.heading)
        truth = load_map(sc.truth)
    net = built.network()
    paths = [save_build(net, out / "map_build_sumo.png", sc.x, sc.y, sc.heading,
                        title="built from a SUMO run: a lane drop (east) and a junction")]
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5))
    for ax, n, t in ((axes[0], truth, "netconvert's OpenDRIVE (the truth)"), (axes[1], net, "built from the trajectories")):
        plot_map(n, ax, labels=False, legend=False, title=t)
        ax.set_xlim(200, 700)
        ax.set_ylim(180, 320)
    fig.tight_layout()
    fig.savefig(out / "map_build_vs_truth.png", dpi=110)
    paths.append(out / "map_build_vs_truth.png")
    plt.close("all")
    del np
    return paths


if __name__ == "__main__":
    print(main(ROOT / "docs" / "figures"))
