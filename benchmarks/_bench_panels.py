"""Benchmark: flatten, nest and write ~1000 panels of a large hexagonal grid-shell.

Target (task brief): 1000 panel DXFs with nesting in < 30 s. Prints the time of each stage,
the sheet count, utilisation and peak memory. ``bench_panels()`` returns the figures. The peer in
the same run: the panel DXFs written one fresh document each, as before 2026-12-06 (the stage
now writes them from one shared document, fabrication.dxf.SharedDocument).
"""

from __future__ import annotations

import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from engine.mesh import PolyMesh


def hex_dome(rows: int = 25, cols: int = 40, radius: float = 0.1, rise_ratio: float = 0.15) -> PolyMesh:
    """Pointy-top hexagonal cells (circumradius ``radius`` m) on an elliptic paraboloid dome
    z = rise (1 - (x/a)^2 - (y/b)^2) over the grid's plan (a, b half sizes, rise = ratio * 2a)."""
    w = np.sqrt(3.0) * radius
    corners = np.array([[np.cos(t), np.sin(t)] for t in np.pi / 6 + np.arange(6) * np.pi / 3]) * radius
    centres = np.array([[c * w + (r % 2) * w / 2, r * 1.5 * radius] for r in range(rows) for c in range(cols)])
    centres -= centres.mean(axis=0)
    points = (centres[:, None, :] + corners[None, :, :]).reshape(-1, 2)
    key = np.round(points / (radius * 1e-3)).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    plan = points[first]
    a, b = np.abs(plan).max(axis=0) * 1.05
    z = rise_ratio * 2 * a * (1 - (plan[:, 0] / a) ** 2 - (plan[:, 1] / b) ** 2)
    faces = tuple(inverse.reshape(-1, 6)[k] for k in range(len(centres)))
    counts = np.bincount(inverse, minlength=len(plan))
    return PolyMesh(nodes=np.column_stack([plan, z]), faces=faces, boundary=counts < 3, supports=counts < 3)


def bench_panels(rows: int = 25, cols: int = 40, folder: str | Path | None = None) -> dict:
    """Run the panel pipeline on a rows x cols hexagonal dome; print and return the timings (s)."""
    from fabrication.nesting_sheets import SheetSettings, nest_sheets, write_sheet_dxfs
    from fabrication.panels import PanelSettings, flatten_panels, write_panel_dxfs, write_panels_csv

    mesh = hex_dome(rows, cols)
    settings = PanelSettings(hole_diameter_mm=5, planarity_tolerance_mm=2)
    sheet_settings = SheetSettings()
    figures: dict = {"panels": 0}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(folder) if folder else Path(tmp)
        t0 = time.perf_counter()
        panels = flatten_panels(mesh, settings)
        t1 = time.perf_counter()
        nesting = nest_sheets(panels, sheet_settings)
        t2 = time.perf_counter()
        write_panel_dxfs(panels, out / "panels", settings)
        t3 = time.perf_counter()
        write_sheet_dxfs(nesting, panels, out / "sheets", settings)
        write_panels_csv(panels, nesting, settings, out / "panels.csv")
        t4 = time.perf_counter()
        _fresh_documents(panels, out / "panels-fresh", settings)
        figures["panel_dxfs_fresh_s"] = time.perf_counter() - t4
    figures.update(panels=len(panels), nonplanar=sum(p.nonplanar for p in panels), flatten_s=t1 - t0,
                   nest_s=t2 - t1, panel_dxfs_s=t3 - t2, sheet_dxfs_csv_s=t4 - t3, total_s=t4 - t0,
                   sheets=nesting.n_sheets, utilisation=nesting.utilisation,
                   sheets_lower_bound=int(np.ceil(sum(p.area_mm2 for p in panels)
                                                  / (sheet_settings.width_mm * sheet_settings.height_mm))),
                   peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    print(f"panels: {figures['panels']} hexagonal panels ({figures['nonplanar']} over 2 mm planarity)")
    print(f"  flatten {figures['flatten_s']:.2f} s | nest {figures['nest_s']:.2f} s "
          f"({figures['sheets']} sheets 1200x600, utilisation {100 * figures['utilisation']:.1f} %; "
          f"area lower bound {figures['sheets_lower_bound']} sheets) | "
          f"panel DXFs {figures['panel_dxfs_s']:.2f} s (one fresh document each: "
          f"{figures['panel_dxfs_fresh_s']:.2f} s) | sheet DXFs + CSV {figures['sheet_dxfs_csv_s']:.2f} s")
    print(f"  total {figures['total_s']:.2f} s (target < 30 s) | peak RSS {figures['peak_rss_mb']:.0f} MB")
    return figures


def _fresh_documents(panels, folder: Path, settings) -> None:
    """The panel DXFs as written before the shared document: a fresh document per panel."""
    from fabrication.dxf import cutting_layers, new_document, save_dxf
    from fabrication.panels import add_panel

    folder.mkdir(parents=True, exist_ok=True)
    for panel in panels:
        doc = new_document(cutting_layers(drill=settings.hole_diameter_mm > 0))
        add_panel(doc.modelspace(), panel, settings=settings, note=True)
        save_dxf(doc, folder / f"{panel.id}.dxf")


if __name__ == "__main__":
    bench_panels()
