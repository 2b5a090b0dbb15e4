"""Sheet nesting speed and yield on cell-like and irregular panels, with and without the free-space
bound (fabrication.nesting_sheets), in the same run.

    .venv/bin/python benchmarks/sheet_nesting.py [--quick] [--run OUT ...]

Cases: the hexagonal panels of a dome (benchmarks/_bench_panels.py) on 1200 x 600 mm sheets and on
6000 x 3210 mm jumbo glass; random convex polygons (3-8 sides, 40-250 mm, squashed) on both. Per case
and variant: seconds, sheets, the area lower bound on sheets and the utilisation. The variant
"whole union" replaces the bound by none (every part on the sheet in every no-fit union), which is
what the nester did before 2026-12-02; both must give the same sheets. ``--run OUT`` adds the panels
of a finished run (its optimised grid and panels.obj, flattened with its own settings, on its stock
sheets), e.g. a 1500-cell roof of benchmarks/any_roof.py.

The peer, ``--peer SECONDS`` (spyrrow, the Python binding of the sparrow strip packer, in the bench
extra): the same parts, with the same spacing and rotations, packed into one strip of the sheet's
height less its margins, in that many seconds. Its length over the sheet's usable length is the
number of sheets a nester would need if parts could run on across the sheets' ends, a relaxation
of the problem: no nester that keeps each part on one sheet can do much better.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_panels import hex_dome  # noqa: E402

from fabrication import nesting_sheets  # noqa: E402
from fabrication.panels import PanelSettings, flatten_panels  # noqa: E402


@dataclass
class _Panel:
    id: str
    outline_mm: np.ndarray
    area_mm2: float


def random_panels(n: int, seed: int) -> list[_Panel]:
    """``n`` random convex polygons, 3-8 sides, circumradius 40-250 mm, squashed by 0.4-1."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        k = int(rng.integers(3, 9))
        t = np.sort(rng.uniform(0, 2 * np.pi, k))
        r, squash = rng.uniform(40, 250), rng.uniform(0.4, 1.0)
        hull = shapely.Polygon(np.column_stack([r * np.cos(t), squash * r * np.sin(t)])).convex_hull
        out.append(_Panel(f"P{i + 1:04d}", np.asarray(hull.exterior.coords)[:-1], hull.area))
    return out


def dome_panels(rows: int, cols: int, radius: float) -> list:
    return flatten_panels(hex_dome(rows, cols, radius=radius), PanelSettings(hole_diameter_mm=0,
                                                                             planarity_tolerance_mm=50))


def run_panels(out: Path) -> tuple[list, list]:
    """The panels of the run in ``out`` as its fabrication stage flattens them, and its stock sheets."""
    import json

    from engine.mesh import PolyMesh
    from workflow.config import Project
    from workflow.stages.optimize import read_panels_obj
    from workflow.stages.polymesh_io import read_polymesh_obj

    project = Project.model_validate(json.loads((out / "manifest.json").read_text())["config"])
    grid = read_polymesh_obj(out / "05-optimize" / "gridshell.obj")
    pieces = read_panels_obj(out / "05-optimize" / "panels.obj")
    settings = project.fabrication.panels.to_settings()
    panels = flatten_panels(PolyMesh(nodes=grid.nodes, faces=tuple(x.loop for x in pieces)), settings)
    return panels, project.fabrication.sheets.to_settings()


def sparrow_sheet_lengths(panels: list, settings: nesting_sheets.SheetSettings, seconds: int) -> tuple[float, float]:
    """The peer: (sheet lengths, strip density) of the parts packed into one strip of the sheet's
    usable height by sparrow (spyrrow) in ``seconds``, one thread, seed 1."""
    import spyrrow

    turns = [0.0, 90.0, 180.0, 270.0] if settings.rotations else [0.0]
    outlines = [np.asarray(p.outline_mm, float) for p in panels]
    items = [spyrrow.Item(f"p{i}", [(float(x), float(y)) for x, y in o - o.mean(axis=0)], 1, turns)
             for i, o in enumerate(outlines)]
    usable_width = settings.width_mm - 2 * settings.margin_mm
    usable_height = settings.height_mm - 2 * settings.margin_mm
    instance = spyrrow.StripPackingInstance("sheets", usable_height, items)
    solution = instance.solve(spyrrow.StripPackingConfig(total_computation_time=seconds, num_workers=1, seed=1,
                                                         min_items_separation=settings.spacing_mm or None))
    return solution.width / usable_width, solution.density


def _without_bound(self, radius, rebuild, settings):
    return np.array([[-math.inf, -math.inf, math.inf, math.inf]])  # one piece: the whole plane


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller cases")
    parser.add_argument("--run", type=Path, action="append", default=[], help="a finished run's folder")
    parser.add_argument("--peer", type=int, default=0, metavar="SECONDS",
                        help="also pack each case into one strip with sparrow (spyrrow) in this many seconds")
    parser.add_argument("--cases", default="", help="comma list of case numbers to run (1-based; --run's follow)")
    args = parser.parse_args()
    small = args.quick
    cases = [
        ("hexagons, dome", dome_panels(25, 40, 0.1), (1200, 600)),
        ("hexagons, dome", dome_panels(20, 30, 0.16) if small else dome_panels(40, 60, 0.16), (6000, 3210)),
        ("random convex", random_panels(300 if small else 800, 1), (1200, 600)),
        ("random convex", random_panels(500 if small else 1500, 2), (6000, 3210)),
    ]
    for out in args.run:
        panels, stocks = run_panels(out)
        stock = stocks[0]
        cases.append((f"{out.name}", [p for p in panels if nesting_sheets.fits_sheet(p, stock)], stock))
    if args.cases:
        cases = [cases[int(k) - 1] for k in args.cases.split(",")]
    bound = nesting_sheets._Sheet.free_parts
    print(f"{'panels':28s} {'sheet mm':>11s} {'variant':12s} {'s':>7s} {'sheets':>6s} {'bound':>5s} {'use %':>6s}")
    for name, panels, sheet in cases:
        settings = sheet if isinstance(sheet, nesting_sheets.SheetSettings) else \
            nesting_sheets.SheetSettings(width_mm=sheet[0], height_mm=sheet[1])
        w, h = f"{settings.width_mm:g}", f"{settings.height_mm:g}"
        lower = math.ceil(sum(p.area_mm2 for p in panels) / (settings.width_mm * settings.height_mm))
        for variant, method in (("free space", bound), ("whole union", _without_bound)):
            nesting_sheets._Sheet.free_parts = method
            t = time.perf_counter()
            nesting = nesting_sheets.nest_sheets(panels, settings)
            seconds = time.perf_counter() - t
            print(f"{f'{len(panels)} {name}':28s} {f'{w}x{h}':>11s} {variant:12s} {seconds:7.1f} "
                  f"{nesting.n_sheets:6d} {lower:5d} {100 * nesting.utilisation:6.1f}", flush=True)
        nesting_sheets._Sheet.free_parts = bound
        if args.peer:
            try:
                t = time.perf_counter()
                lengths, density = sparrow_sheet_lengths(panels, settings, args.peer)
                print(f"{f'{len(panels)} {name}':28s} {f'{w}x{h}':>11s} {'peer: strip':12s} "
                      f"{time.perf_counter() - t:7.1f} {lengths:6.2f} {lower:5d} {100 * density:6.1f}  "
                      "(sparrow: sheet lengths of one strip, its density)", flush=True)
            except ImportError:
                print("peer: spyrrow is not installed (pip install spyrrow)", flush=True)


if __name__ == "__main__":
    main()
