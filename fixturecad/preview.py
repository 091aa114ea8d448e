"""preview.png: the fixture with its sensing features coloured and labelled, and the default touch plan.

Rendering needs matplotlib only (Agg, no pyplot). ``fixturecad build`` runs it
in a side process (:mod:`fixturecad.sideprocess`) so that importing matplotlib
and drawing overlap the CAD work.
"""

import numpy as np

FEATURE_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf")
INERT_COLOUR = "#c8c8c8"
TOUCH_COLOUR = "#111111"
SENSOR_COLOUR = "#444444"
SUBDIVISION = 15  # triangles longer than size / this are split, so depth sorting works on big flat faces
FRAME_AXIS_FRACTION = 0.3  # length of the drawn frame axes, as a fraction of the half size of the view
VIEWS = ((28.0, -60.0), (-28.0, 120.0))  # (elevation, azimuth) deg: front-top and back-bottom
TABLE_CHAR_IN = 0.07  # width of a character of the plan's table (8 pt monospace), inches
TABLE_MARGIN_IN = 0.9  # room beside the table for the views' axis labels, inches


def feature_colours(ids) -> dict:
    """The colour (hex) of each feature id, in features.json order: the preview's, the STEP's and the 3MF's."""
    return {fid: FEATURE_COLOURS[i % len(FEATURE_COLOURS)] for i, fid in enumerate(ids)}


def view_from_direction(direction) -> tuple:
    """(elevation, azimuth) in degrees of a camera looking from ``direction`` towards the origin."""
    x, y, z = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    return float(np.degrees(np.arcsin(z))), float(np.degrees(np.arctan2(y, x)))


def scene(title: str, faces: list, features: list, touches: list, views=VIEWS, sensors=()) -> dict:
    """The data a preview needs, plain numpy.

    faces: ``[(vertices (n, 3), triangles (m, 3), feature id or None)]``;
    features: ``[{"id", "kind", "element", "anchor" (3,), "normal" (3,) or None, "segment" ((2, 3) for
    lines or None)}]``; touches: ``[{"point" (3,), "normal" (3,) or None, "label" str, "text" str}]``;
    views: two (elevation, azimuth); sensors: ``[{"kind": "plane" | "line", "points" (4, 3) or (2, 3)}]``,
    the plane and line sensors of the plan, each with the "normal" of its feature for hiding. Labels and touches whose outward normal faces away from a view
    are left out of it (matplotlib would draw them through the solid).
    """
    return {"title": title, "faces": faces, "features": features, "touches": touches, "views": views,
            "sensors": list(sensors)}


def fixture_scene(template, features, matches: dict, parts) -> dict:
    """Preview data: tessellated faces tagged with their feature, labels, default touch plan."""
    face_owner = {}
    for feature in features:
        if feature.surface:
            for index in matches[feature.id]:
                face_owner[index] = feature.id
    faces = []
    for index, (_, nodes, triangles) in enumerate(parts):
        faces.append((nodes, triangles, face_owner.get(index)))
    plan = template.touch_plans()["default"]
    touches, number = [], 0
    by_id = {feature.id: feature for feature in features}
    for entry in plan.touches:
        for point in entry["points"]:
            number += 1
            normal = _label_normal(by_id[entry["feature"]], np.array(point), features)
            touches.append({"point": np.array(point), "normal": normal, "label": str(number), "feature": entry["feature"],
                            "text": f"{number:>2} {entry['contact']:<10} {entry['feature']}"})
    feature_rows = []
    for feature in features:
        segment = None
        if feature.kind == "line":
            t0, t1 = feature.extent.interval
            segment = np.array([feature.point + t0 * feature.direction, feature.point + t1 * feature.direction])
        if segment is not None:
            nodes = segment[0] + np.linspace(0.1, 0.9, 9)[:, None] * (segment[1] - segment[0])
        else:
            nodes = np.vstack([parts[i][1] for i in matches[feature.id] if i < len(parts)] or [feature.point])
        # keep labels off the touch markers and the frame's axes
        frame = [k * FRAME_AXIS_FRACTION * _span(parts) / 2 * axis for axis in np.eye(3) for k in (0.0, 0.5, 1.0)]
        anchor = _label_place(nodes, [t["point"] for t in touches] + frame, 0.22 * _span(parts))
        if anchor is None:  # a small feature crowded with touches: above their middle
            anchor = np.mean([t["point"] for t in touches if t["feature"] == feature.id] or nodes, axis=0)
        normal = _label_normal(feature, anchor, features)
        if normal is not None:  # off the surface, or off a line along the faces' mean normal
            anchor = anchor + 0.08 * _span(parts) * normal
        feature_rows.append({"id": feature.id, "kind": feature.kind, "element": feature.element,
                             "anchor": anchor, "normal": normal, "segment": segment})
    parameters = ", ".join(f"{k} {v:g}" for k, v in template.parameters_json().items() if k != "base")
    title = (f"{template.name} ({parameters}{', base' if template.base else ''}): {template.contact_class}"
             f" - default plan, {number} touches")
    views = tuple(view_from_direction(d) for d in template.VIEW_DIRECTIONS)
    label_normals = {row["id"]: row["normal"] for row in feature_rows}
    sensors = [{**_sensor_drawing(entry["sensor"], 0.35 * _span(parts)), "normal": label_normals[entry["feature"]]}
               for entry in plan.touches if entry.get("sensor", {}).get("kind") in ("plane", "line", "cylinder")]
    return scene(title, faces, feature_rows, touches, views, sensors)


def plan_scene(title, vertices, triangles, features, entries, plan_name, views=VIEWS) -> dict:
    """Preview data of a touch plan on the fixture's mesh (vertices (n, 3), triangles (m, 3), mm): triangles
    on a sensing feature's patch take its colour, the plan's touches (entries with their ``approaches``)
    are numbered in the plan's order."""
    centroids = vertices[triangles].mean(axis=1)
    owner = np.full(len(triangles), None, dtype=object)
    for feature in features:
        if feature.surface:
            on = (np.abs(feature.signed_distance(centroids)) < 0.01 * _span([(None, vertices, None)])) & \
                feature.contains(centroids, 1e-3)
            owner[on & (owner == None)] = feature.id  # noqa: E711 (elementwise)
    faces = [(vertices, triangles[owner == fid], fid) for fid in [None] + [f.id for f in features]
             if np.any(owner == fid)]
    touches, number = [], 0
    for entry in entries:
        for point, approach in zip(entry["points"], entry["approaches"]):
            number += 1
            touches.append({"point": np.array(point), "normal": -np.array(approach), "label": str(number),
                            "feature": entry["feature"],
                            "text": f"{number:>2} {entry['contact']:<10} {entry['feature']}"})
    rows = []
    for feature in features:
        if feature.surface and np.any(owner == feature.id):
            nodes = centroids[owner == feature.id]
            anchor = _label_place(nodes, [t["point"] for t in touches], 0.15 * _span([(None, vertices, None)]))
            anchor = nodes.mean(axis=0) if anchor is None else anchor
            rows.append({"id": feature.id, "kind": feature.kind, "element": feature.element, "anchor": anchor,
                         "normal": feature.normal_at(anchor[None])[0], "segment": None})
    return {**scene(title, faces, rows, touches, views), "plan": plan_name}


def _label_place(nodes, touch_points, clearance):
    """Where a feature's label goes: the node nearest the feature's centre among those at least
    ``clearance`` mm from every touch; None when none is."""
    nodes = np.asarray(nodes, dtype=float)
    if not len(touch_points):
        return nodes.mean(axis=0)
    away = np.linalg.norm(nodes[:, None, :] - np.asarray(touch_points)[None], axis=2).min(axis=1)
    clear = away >= clearance
    if not clear.any():
        return None
    candidates = nodes[clear]
    return candidates[int(np.argmin(np.linalg.norm(candidates - nodes.mean(axis=0), axis=1)))]


def _sensor_drawing(sensor: dict, size: float) -> dict:
    """A plane, line or cylinder sensor of the plan as something to draw: a square of the plane, a segment
    of the line or of the cylinder's axis (a ball's touch is drawn as its touch)."""
    point = np.array(sensor["point"])
    if sensor["kind"] in ("line", "cylinder"):
        d = np.array(sensor.get("direction", sensor.get("axis")))
        return {"kind": "line", "points": np.array([point - size * d, point + size * d])}
    n = np.array(sensor["normal"])
    a = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    corners = [point + size / 2 * (sa * a + sb * b) for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return {"kind": "plane", "points": np.array(corners)}


def _label_normal(feature, anchor, features):
    """Outward normal used to hide a label from views that face away; for a line or point, the
    mean normal of the surfaces that meet there."""
    if feature.kind not in ("line", "point"):
        return feature.normal_at(anchor)[0]
    near = [f.normal_at(anchor)[0] for f in features
            if f.surface and abs(f.signed_distance(anchor)[0]) < 1e-6 and f.contains(anchor)[0]]
    total = np.sum(near, axis=0) if near else np.zeros(3)
    return total / np.linalg.norm(total) if np.linalg.norm(total) > 1e-9 else None


def _span(parts) -> float:
    nodes = np.vstack([p[1] for p in parts])
    return float((nodes.max(axis=0) - nodes.min(axis=0)).max())


def render(data: dict, path) -> None:
    """Draw ``data`` (see :func:`scene`) into a PNG at ``path``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    colours = feature_colours([f["id"] for f in data["features"]])
    all_points = np.vstack([v for v, _, _ in data["faces"]])
    low, high = all_points.min(axis=0), all_points.max(axis=0)
    centre, half = (low + high) / 2, (high - low).max() / 2 * 1.05
    max_edge = (high - low).max() / SUBDIVISION
    light = np.array([0.4, -0.5, 0.75]) / np.linalg.norm([0.4, -0.5, 0.75])

    listing = "\n".join([f"{data.get('plan', 'default')} touch plan"] + [t["text"] for t in data["touches"]]) \
        if data["touches"] else ""
    # The plan's table in a column of its own between the views, wide enough for its longest line.
    table_in = max(map(len, listing.splitlines()), default=0) * TABLE_CHAR_IN + TABLE_MARGIN_IN if listing else 0.0
    figure = Figure(figsize=(13 + table_in, 6.5), dpi=100)
    FigureCanvasAgg(figure)
    grid = figure.add_gridspec(1, 3, width_ratios=(6.5, max(table_in, 1e-3), 6.5), wspace=0.0)
    for panel, (elev, azim) in enumerate(data.get("views", VIEWS)):
        ax = figure.add_subplot(grid[0, 2 * panel], projection="3d")
        e, a = np.radians(elev), np.radians(azim)
        camera = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])

        def seen(normal):
            """Labels on faces turned away from this view would show through: leave them out."""
            return normal is None or float(np.dot(normal, camera)) > 0.05

        # one collection, so matplotlib depth-sorts every triangle against every other; what is
        # drawn after it (sensors, edges, touches, labels) goes on top
        ax.computed_zorder = False
        all_tris, all_colours = [], []
        for vertices, triangles, feature_id in data["faces"]:
            tris = _subdivide(vertices[triangles], max_edge)
            normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
            normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
            shade = 0.55 + 0.45 * np.abs(normals @ light)
            base = np.array(rgb(colours.get(feature_id, INERT_COLOUR)))
            all_tris.append(tris)
            all_colours.append(np.clip(base[None, :] * shade[:, None], 0, 1))
        face_colours = np.concatenate(all_colours)  # edges in the face colour close antialiasing seams
        ax.add_collection3d(Poly3DCollection(np.concatenate(all_tris), facecolors=face_colours,
                                             edgecolors=face_colours, linewidths=0.3, zorder=1))
        for feature in data["features"]:
            if feature.get("segment") is not None and seen(feature.get("normal")):
                seg = np.asarray(feature["segment"])
                ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], color=colours[feature["id"]], linewidth=4, zorder=5)
            anchor = np.asarray(feature["anchor"])
            if not seen(feature.get("normal")):
                continue
            ax.text(*anchor, f"{feature['id']} ({feature['element']})", color=colours[feature["id"]],
                    fontsize=9, fontweight="bold", ha="center", zorder=10,
                    bbox={"facecolor": "white", "alpha": 0.75, "edgecolor": "none", "pad": 1.0})
        for sensor in data.get("sensors", []):
            if not seen(sensor.get("normal")):
                continue
            points = np.asarray(sensor["points"])
            if sensor["kind"] == "plane":
                ax.add_collection3d(Poly3DCollection([points], facecolors=(0.1, 0.1, 0.1, 0.18),
                                                     edgecolors=SENSOR_COLOUR, linestyles="dashed"))
            else:
                ax.plot(points[:, 0], points[:, 1], points[:, 2], color=SENSOR_COLOUR, linestyle="--", linewidth=1.5)
        visible = [t for t in data["touches"] if seen(t.get("normal"))]
        if visible:
            points = np.array([t["point"] for t in visible])
            ax.scatter(points[:, 0], points[:, 1], points[:, 2], color=TOUCH_COLOUR, s=26, depthshade=False, zorder=20)
            for touch in visible:
                ax.text(*touch["point"], f" {touch['label']}", color=TOUCH_COLOUR, fontsize=9, fontweight="bold", zorder=21)
        _frame_axes(ax, FRAME_AXIS_FRACTION * half)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.set_xlabel("X mm")
        ax.set_ylabel("Y mm")
        ax.set_zlabel("Z mm")
        ax.view_init(elev=elev, azim=azim)
    handles = [Patch(color=colours[f["id"]], label=f"{f['id']}: {f['kind']} ({f['element']})") for f in data["features"]]
    handles.append(Line2D([], [], marker="o", linestyle="", color=TOUCH_COLOUR, label=f"touch of the {data.get('plan', 'default')} plan"))
    handles.append(Line2D([], [], marker="s", color="#d00000", markerfacecolor="black", markeredgecolor="black",
                          label="fixture frame: origin, X Y Z"))
    if data.get("sensors"):
        handles.append(Line2D([], [], linestyle="--", color=SENSOR_COLOUR, label="plane / line sensor"))
    if listing:
        figure.text(0.5, 0.88, listing, ha="center", va="top", multialignment="left", fontsize=8, family="monospace",
                    bbox={"facecolor": "white", "edgecolor": "#888888", "alpha": 0.85})
    figure.legend(handles=handles, loc="lower center", ncol=(len(handles) + 1) // 2, fontsize=9, frameon=False)
    figure.suptitle(data["title"], fontsize=11)
    figure.subplots_adjust(left=0.02, right=0.98, top=0.9, bottom=0.1)
    figure.savefig(path)


def _frame_axes(ax, length: float) -> None:
    """The fixture frame: its origin and X, Y, Z axes (red, green, blue), drawn over the solid."""
    for axis, colour in zip("XYZ", ("#d00000", "#00a000", "#0000d0")):
        tip = length * np.eye(3)["XYZ".index(axis)]
        ax.plot([0, tip[0]], [0, tip[1]], [0, tip[2]], color=colour, linewidth=2.5, zorder=30)
        ax.text(*(1.12 * tip), axis, color=colour, fontsize=9, fontweight="bold", ha="center", va="center", zorder=31)
    ax.scatter([0], [0], [0], color="black", marker="s", s=18, depthshade=False, zorder=31)


def _subdivide(tris, max_edge: float, levels: int = 5):
    """Split triangles (m, 3, 3) into four at their edge midpoints until no edge exceeds ``max_edge``."""
    for _ in range(levels):
        edges = np.linalg.norm(tris - np.roll(tris, 1, axis=1), axis=2).max(axis=1)
        big = edges > max_edge
        if not big.any():
            break
        t = tris[big]
        m01, m12, m20 = (t[:, 0] + t[:, 1]) / 2, (t[:, 1] + t[:, 2]) / 2, (t[:, 2] + t[:, 0]) / 2
        split = np.concatenate([
            np.stack([t[:, 0], m01, m20], axis=1), np.stack([m01, t[:, 1], m12], axis=1),
            np.stack([m20, m12, t[:, 2]], axis=1), np.stack([m01, m12, m20], axis=1),
        ])
        tris = np.concatenate([tris[~big], split])
    return tris


def rgb(colour: str):
    """(r, g, b) in [0, 1] of a hex colour."""
    colour = colour.lstrip("#")
    return [int(colour[i : i + 2], 16) / 255 for i in (0, 2, 4)]


