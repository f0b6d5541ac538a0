"""The audit for people: a text table of a report, and a diagnostic picture of one instance."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

from l3mvn.core.errors import L3MVNError
from l3mvn.core.writing import write_file
from l3mvn.run.audit.records import REASONS, AuditReport, InstanceAudit, instance_labels
from l3mvn.run.viz import category_color
from l3mvn.world.scenes.scene import SceneMap


def format_report(report: AuditReport) -> str:
    """Per floor: instances, confirmable and per-reason counts; then one line per instance that is
    not confirmable from inside its success region; then episodes."""
    insts = report.instances
    ok = sum(i.confirmable for i in insts)
    share = f" ({ok / len(insts):.1%})" if insts else ""
    h, w = report.frame
    lines = [
        f"{report.source or '-'} / {report.split or '-'}: rule {report.rule}, frame {h}x{w}: "
        f"{len(insts)} goal instances on {len(report.floors)} floors, {ok} confirmable from their "
        f"success region{share}; {report.seconds:.1f} s"
    ]
    short = {
        "no_floor": "nofloor",
        "no_region": "noregn",
        "unreachable": "unreach",
        "occluded": "occlud",
        "outside_only": "outside",
    }
    heads = [short.get(r, r) for r in REASONS]
    lines.append(f"{'scene/floor':<18}{'inst':>5}{'conf':>5}" + "".join(f"{x:>8}" for x in heads) + f"{'s':>7}")
    for f in report.floors:
        c = Counter(i.reason for i in f.instances)
        lines.append(
            f"{f.key:<18}{len(f.instances):>5}{sum(i.confirmable for i in f.instances):>5}"
            + "".join(f"{c[r]:>8}" for r in REASONS)
            + f"{f.seconds:>7.1f}"
        )
    total = report.reason_counts()
    lines.append(f"{'total':<18}{len(insts):>5}{ok:>5}" + "".join(f"{total[r]:>8}" for r in REASONS))
    bad = [i for i in insts if not i.confirmable]
    if bad:
        lines.append("")
        lines.append(
            "not confirmable from inside the success region (gap: to walkable floor; nearest: "
            "nearest confirming pose within the search radius):"
        )
        lines.append(
            f"{'scene/floor':<18}{'category':<14}{'id':>3} {'centroid':>11} {'reason':<13}"
            f"{'gap_m':>6}{'nearest_m':>10}{'max_px':>8}"
        )
        for i in bad:
            cen = f"{i.centroid[0]},{i.centroid[1]}"
            lines.append(
                f"{i.scene + '/' + str(i.floor):<18}{i.category:<14}{i.instance_id:>3} {cen:>11} "
                f"{i.reason:<13}{_fmt(i.gap_m):>6}{_fmt(i.nearest_confirmable_m):>10}{i.max_pixels:>8}"
            )
    eps = report.episodes
    if eps:
        why = Counter(e.reason for e in eps if not e.confirmable)
        lines.append("")
        lines.append(
            f"episodes: {len(eps)}, goal confirmable from the success region on the start's side: "
            f"{sum(e.confirmable for e in eps)}"
            + (f"; not: {', '.join(f'{k} {v}' for k, v in why.most_common())}" if why else "")
        )
        for e in eps:
            if not e.confirmable:
                lines.append(f"  {e.key} {e.goal}: {e.reason}")
    return "\n".join(lines)


def write_diagnostic_png(
    out_dir: str | Path,
    scene: SceneMap,
    walls: np.ndarray,
    inst: InstanceAudit,
    region: np.ndarray,
    tested: np.ndarray,
    rgb: np.ndarray | None,
) -> Path:
    """Top-down crop (walls dark, walkable floor light, other free floor mid, success region green,
    the instance in its category colour, tested poses blue, the best pose red with its heading)
    beside the best view's RGB."""
    res, pad = scene.resolution_m, 40
    labels, _ = instance_labels(scene, inst.category)
    fp = labels == inst.instance_id
    rows, cols = np.nonzero(fp | region)
    r0, r1 = max(rows.min() - pad, 0), min(rows.max() + pad + 1, scene.shape[0])
    c0, c1 = max(cols.min() - pad, 0), min(cols.max() + pad + 1, scene.shape[1])
    win = (slice(r0, r1), slice(c0, c1))
    img = np.full((r1 - r0, c1 - c0, 3), 20, np.uint8)
    img[scene.free[win]] = (110, 110, 110)
    img[scene.walkable[win]] = (190, 190, 190)
    img[region[win] & scene.walkable[win]] = (150, 215, 150)
    img[walls[win]] = (60, 50, 45)
    img[scene.object_any[win]] = (95, 80, 110)
    img[fp[win]] = category_color(inst.category)
    scale = max(1, min(6, 480 // max(img.shape[:2])))
    img = cv2.resize(img, (img.shape[1] * scale, img.shape[0] * scale), interpolation=cv2.INTER_NEAREST)
    for r, c in tested:
        if r0 <= r < r1 and c0 <= c < c1:
            centre = (int((c - c0 + 0.5) * scale), int((r - r0 + 0.5) * scale))
            cv2.circle(img, centre, max(2, scale), (40, 80, 230), -1)
    if inst.best_pose is not None:
        x, y, heading, _ = inst.best_pose
        px, py = (x / res - c0) * scale, (y / res - r0) * scale
        tip = (px + 12 * scale * math.cos(math.radians(heading)), py + 12 * scale * math.sin(math.radians(heading)))
        cv2.line(img, (int(px), int(py)), (int(tip[0]), int(tip[1])), (230, 30, 30), max(1, scale // 2))
        cv2.circle(img, (int(px), int(py)), max(3, scale + 1), (230, 30, 30), -1)
    view = (
        np.zeros((img.shape[0], img.shape[0] * 4 // 3, 3), np.uint8)
        if rgb is None
        else cv2.resize(rgb, (rgb.shape[1] * img.shape[0] // rgb.shape[0], img.shape[0]), interpolation=cv2.INTER_AREA)
    )
    panel = np.concatenate([img, np.zeros((img.shape[0], 4, 3), np.uint8), view], axis=1)
    text = (
        f"{inst.scene}/{inst.floor} {inst.category} #{inst.instance_id}: {inst.reason or 'confirmable'} "
        f"px {inst.max_pixels} mapped {inst.max_mapped_cells}"
    )
    cv2.putText(panel, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    path = Path(out_dir) / f"{inst.scene}_{inst.floor}_{inst.category.replace(' ', '-')}_{inst.instance_id}.png"
    ok, png = cv2.imencode(".png", cv2.cvtColor(panel, cv2.COLOR_RGB2BGR))
    if not ok:
        raise L3MVNError(f"cannot encode the diagnostic picture {path.name}")
    return write_file(path, png.tobytes(), "diagnostic picture")


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"
