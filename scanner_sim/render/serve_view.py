"""A pass in a local interactive viewer (``scanner-sim view RUN_DIR --serve``): viser, the ``serve`` extra, for passes
too large for one HTML page. The server listens on 127.0.0.1 only and runs until Ctrl-C (exit 130)."""

from __future__ import annotations

import math
import time

import numpy as np

from scanner_sim.render.point_colours import point_rgb
from scanner_sim.render.web_view import COLOURINGS, MESH_MAX_TRIANGLES, PassFiles, cluster_mesh, sampled_points

#: The only address the viewer listens on: this machine, never the network.
HOST = "127.0.0.1"
DEFAULT_PORT = 8080
#: Points the viewer shows at most by default (one in every k in file order above it, as the HTML page).
DEFAULT_MAX_POINTS = 5_000_000


def _viser():
    try:
        import viser
    except ImportError:
        raise ValueError("--serve: needs viser, the serve extra: pip install 'muls-scanner[serve]' (or use --html)"
                         ) from None
    return viser


def serve(files: PassFiles, *, port: int = DEFAULT_PORT, max_points: int = DEFAULT_MAX_POINTS,
          color: str | None = None, announce=print) -> None:
    """Serve the points of ``files`` (coloured by ``color``, switchable), the faded scene mesh and the trajectory at
    http://127.0.0.1:PORT until interrupted; ``announce`` gets the address line once the server listens."""
    from scanner_sim.io import read_scene_ply, read_trajectory_csv

    viser = _viser()
    n, stride, _, xyz, lo, hi, centre, values = sampled_points(files, max_points)
    scene = read_scene_ply(files.scene_ply) if files.scene_ply is not None else None
    first = color or ("depth" if scene is not None else "class")
    spacing = math.sqrt(max(float((hi[0] - lo[0]) * (hi[1] - lo[1])), 1e-6) / max(len(xyz), 1))

    def colours(name: str) -> np.ndarray:
        return np.rint(point_rgb(values[name], name) * 255).astype(np.uint8)

    server = viser.ViserServer(host=HOST, port=port, verbose=False)
    try:
        cloud = server.scene.add_point_cloud("/points", (xyz - centre).astype(np.float32), colours(first),
                                             point_size=0.8 * spacing, precision="float32")
        if scene is not None and len(scene["faces"]):
            v, f = cluster_mesh(scene["vertices"], scene["faces"], MESH_MAX_TRIANGLES)
            server.scene.add_mesh_simple("/scene", (v - centre).astype(np.float32), f.astype(np.uint32),
                                         color=(200, 204, 208), opacity=0.25, side="double")
        if files.trajectory is not None:
            table = read_trajectory_csv(files.trajectory)
            track = np.column_stack([table["x_m"], table["y_m"], table["z_m"]]) - centre
            if len(track) > 1:
                server.scene.add_line_segments("/trajectory", np.stack([track[:-1], track[1:]], axis=1),
                                               (255, 255, 255), thickness=2.0, thickness_units="screen")
        rule = f"all {n:,} points" if stride == 1 else f"one point in every {stride} in file order ({len(xyz):,} of {n:,})"
        server.gui.add_markdown(f"**{', '.join(f.name for f in files.clouds)}**: {rule}")
        choice = server.gui.add_dropdown("colour by", options=tuple(COLOURINGS), initial_value=first)

        @choice.on_update
        def _recolour(_event) -> None:
            cloud.colors = colours(choice.value)

        announce(f"http://{HOST}:{server.get_port()}  ({len(xyz):,} points; Ctrl-C to stop)")
        while True:
            time.sleep(3600.0)
    finally:
        server.stop()
