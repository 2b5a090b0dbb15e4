"""Analysis and remeshing pictures: each PNG is written, re-read by matplotlib and not blank."""

from __future__ import annotations

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib")
from matplotlib import image  # noqa: E402

from engine.geometry.parametric import cap  # noqa: E402
from engine.remeshing.grids import quad_grid  # noqa: E402
from workflow.plots.analysis import plot_axial_forces, plot_buckling_modes, plot_response, plot_utilisation  # noqa: E402
from workflow.plots.remesh import plot_gridshell  # noqa: E402


@pytest.fixture(scope="module")
def grid():
    mesh = cap()
    support = np.zeros(mesh.n_vertices, dtype=bool)
    support[mesh.boundary_loops[0]] = True
    return quad_grid(mesh, total_length=12.0 * np.sqrt(mesh.area), support_vertices=support)


def _check_png(path):
    assert path.exists() and path.stat().st_size > 2000
    pixels = image.imread(path)
    assert pixels.ndim == 3 and pixels.shape[0] > 200 and pixels.shape[1] > 200
    rgb = pixels[..., :3].reshape(-1, 3)
    assert len(np.unique(np.round(rgb, 2), axis=0)) > 20, "more than a few colours"
    assert (rgb.std(axis=0) > 0.02).any(), "not one colour"
    assert not list(path.parent.glob("*.tmp*")), "no temporary file left behind"


@pytest.mark.parametrize("color_by", ["degree", "planarity"])
def test_gridshell_picture(grid, tmp_path, color_by):
    _check_png(plot_gridshell(grid, tmp_path / f"grid_{color_by}.png", color_by=color_by, title="cap"))


def test_a_grid_of_mixed_cells_draws_whatever_matplotlibs_padding_holds(grid, tmp_path, monkeypatch):
    """matplotlib pads cells of fewer sides with np.empty and autoscaled the 3-D axes from that
    padding too: the vault template's optimize stage failed at random in CI ("Axis limits cannot be
    NaN or Inf", after overflows in its limits). Here the padding holds +-1.6e308 every time, as it
    did there, and an overflow is an error."""
    import types
    import warnings

    from mpl_toolkits.mplot3d import art3d

    assert len(set(grid.face_degrees.tolist())) > 1, "the grid mixes cells of different sides"
    numpy = types.SimpleNamespace(**{name: getattr(np, name) for name in dir(np) if not name.startswith("__")})
    numpy.empty = lambda shape, *args, **kwargs: np.resize([-1.6e308, 1.6e308], shape)
    monkeypatch.setattr(art3d, "np", numpy)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        _check_png(plot_gridshell(grid, tmp_path / "padded.png", color_by="degree"))


def test_a_flat_grid_is_framed_with_a_height_and_draws_cleanly(tmp_path):
    """A flat roof (zero height) is drawn in 3-D with a height of 5 % of its plan and limits that
    match the box at true scale (a zero-height range made matplotlib's projection overflow);
    a curved one keeps its true height."""
    import warnings

    from engine.geometry.parametric import grid_triangles
    from engine.mesh import TriMesh
    from workflow.plots._common import frame_3d, pyplot

    plt = pyplot()
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    frame_3d(ax, np.array([[0.0, 0.0, 2.0], [10.0, 4.0, 2.0]]))
    assert ax.get_zlim() == pytest.approx((1.75, 2.25))
    assert ax.get_xlim() == pytest.approx((0.0, 10.0)) and ax.get_ylim() == pytest.approx((0.0, 4.0))
    frame_3d(ax, np.array([[0.0, 0.0, 0.0], [10.0, 4.0, 3.0]]))
    assert ax.get_zlim() == pytest.approx((0.0, 3.0))
    box = ax.get_box_aspect()
    assert box[0] / box[2] == pytest.approx(10.0 / 3.0) and box[1] / box[2] == pytest.approx(4.0 / 3.0)
    plt.close(fig)

    xs = np.linspace(0.0, 10.0, 11)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    flat = TriMesh(vertices=np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], faces=grid_triangles(10, 10))
    support = np.zeros(flat.n_vertices, dtype=bool)
    support[flat.boundary_loops[0]] = True
    grid = quad_grid(flat, total_length=12.0 * np.sqrt(flat.area), support_vertices=support)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        _check_png(plot_gridshell(grid, tmp_path / "flat.png", title="flat"))


def test_utilisation_and_axial_force_pictures(grid, tmp_path):
    beams = grid.edges
    rng = np.random.default_rng(1)
    utilisation = rng.uniform(0.0, 1.3, len(beams))
    _check_png(plot_utilisation(grid.nodes, beams, utilisation, tmp_path / "utilisation.png", title="u"))
    forces = rng.normal(0.0, 20e3, len(beams))
    _check_png(plot_axial_forces(grid.nodes, beams, forces, tmp_path / "axial.png"))


def test_buckling_mode_picture(grid, tmp_path):
    n = grid.n_nodes
    centre = grid.nodes[:, :2] - grid.nodes[:, :2].mean(axis=0)
    modes = np.zeros((2, n, 6))
    modes[0, :, 2] = np.cos(3 * centre[:, 0])
    modes[1, :, 2] = np.sin(2 * centre[:, 1])
    _check_png(plot_buckling_modes(grid.nodes, grid.edges, modes, np.array([4.2, 5.1]), tmp_path / "modes.png"))


def test_response_picture(tmp_path):
    t = np.linspace(0, 1, 40)
    curves = {"perfect": np.column_stack([3 * np.sin(2 * t), -0.05 * t]),
              "LB mode 1 +": np.column_stack([2.4 * np.sin(2 * t), -0.06 * t])}
    _check_png(plot_response(curves, tmp_path / "response.png", worst="LB mode 1 +", required=1.5))


@pytest.mark.parametrize("bad", ["nan", "inf", "huge", "empty", "all"])
def test_response_picture_copes_with_curves_that_cannot_be_drawn(tmp_path, bad):
    """A path that diverged (NaN, inf, values near the float range) or is empty: the PNG is
    written, the good curve drawn, the bad one named in the title (nothing finite) or counted in
    the legend (some points left out). Before, load factors of +-1e308 ended in a LinAlgError from
    matplotlib's transforms."""
    t = np.linspace(0, 1, 40)
    good = np.column_stack([3 * np.sin(2 * t), -0.05 * t])
    broken = {"nan": np.full((5, 2), np.nan), "inf": np.array([[0.0, 0.0], [1.0, -np.inf], [np.inf, -0.1]]),
              "huge": np.array([[-1e308, 0.0], [1e308, -1.0]]), "empty": np.zeros((0, 2)),
              "all": np.full((3, 2), np.inf)}[bad]
    curves = {"perfect": broken} if bad == "all" else {"perfect": good, "worst (mode1+)": broken}
    path = plot_response(curves, tmp_path / "response.png", worst="worst (mode1+)", required=1.5,
                         title="grids of equal length")
    _check_png(path)


def test_response_picture_with_some_points_left_out_keeps_the_curve(tmp_path):
    from workflow.plots.analysis import _drawable

    curve = np.array([[0.0, 0.0], [0.5, -0.01], [np.nan, -0.02], [1.0, -np.inf], [1.2, -0.03]])
    xy, dropped = _drawable(curve)
    assert dropped == 2
    np.testing.assert_allclose(xy, [[0.0, 0.0], [10.0, 0.5], [30.0, 1.2]])
    assert _drawable(np.zeros((0, 2))) == (None, 0) and _drawable(np.full((2, 2), np.nan))[0] is None
    _check_png(plot_response({"worst": curve}, tmp_path / "response.png", worst="worst"))


# --- the report's captions say what the pictures draw (issue 18: "supports (black)" under red ones) --

@pytest.fixture
def drawn(monkeypatch):
    """The figures the plotting functions save, kept (with their artists) for inspection."""
    from matplotlib.figure import Figure

    figures = []
    savefig = Figure.savefig

    def keep(self, *args, **kwargs):
        figures.append(self)
        return savefig(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return figures


def _caption(relative: str) -> str:
    from workflow.stages.report import FIGURES

    return next(caption for figures in FIGURES.values() for path, caption in figures if path == relative)


def _is(colour: str, rgba) -> bool:
    r, g, b = np.asarray(rgba, dtype=float)[:3]
    return {"red": r > 0.6 and g < 0.35 and b < 0.35, "blue": b > 0.5 and r < 0.45,
            "black": max(r, g, b) < 0.25, "green": g > 0.5 and r < 0.45 and b < 0.45}[colour]


def test_the_surface_caption_names_the_colour_the_supports_are_drawn_in(drawn, tmp_path):
    from workflow.plots.surface import plot_surface

    mesh = cap()
    supports = np.asarray(mesh.boundary_loops[0])
    plot_surface(mesh, supports, tmp_path / "surface.png")
    (colour,) = [c for c in ("red", "blue", "black", "green") if f"({c})" in _caption("01-surface/surface.png")]
    dots = [c for ax in drawn[-1].axes for c in ax.collections if c.get_label().endswith("supports")
            or c.get_label().endswith("supported nodes")]
    assert len(dots) == 2 and all(len(d.get_offsets()) == len(supports) for d in dots)
    assert all(_is(colour, rgba) for d in dots for rgba in d.get_facecolor())


@pytest.mark.parametrize("shape", ["courtyard", "cap", "vault"])
def test_the_surface_pictures_labels_stay_apart(drawn, tmp_path, shape):
    """Every axis label of the surface picture, the 3-D view's z label among them, keeps clear of
    the others as drawn (the z label ran into the plan's y label on the courtyard template)."""
    from engine.geometry import parametric
    from workflow.plots.surface import plot_surface

    mesh = getattr(parametric, shape)()
    plot_surface(mesh, np.asarray(mesh.boundary_loops[0]), tmp_path / "surface.png")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    figure = drawn[-1]
    canvas = FigureCanvasAgg(figure)  # drawn again as saved: the 3-D labels are placed at draw time
    canvas.draw()
    renderer = canvas.get_renderer()
    labels = [axis.label for ax in figure.axes for axis in (ax.xaxis, ax.yaxis, getattr(ax, "zaxis", None))
              if axis is not None and axis.label.get_text()]
    boxes = [label.get_window_extent(renderer) for label in labels]
    assert len(boxes) >= 6
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            assert not boxes[i].overlaps(boxes[j]), (labels[i].get_text(), labels[j].get_text())


def test_the_axial_force_caption_says_which_colour_is_compression(drawn, grid, tmp_path):
    """'compression red, tension blue': each beam's drawn colour by the sign of its force."""
    import re

    caption = _caption("06-analysis/axial.png")
    words = dict(re.findall(r"(compression|tension) (red|blue)", caption))
    assert set(words) == {"compression", "tension"}
    forces = np.where(np.arange(len(grid.edges)) % 2 == 0, -10e3, 10e3)
    plot_axial_forces(grid.nodes, grid.edges, forces, tmp_path / "axial.png")
    (lines,) = [c for c in drawn[-1].axes[0].collections if c.get_array() is not None]
    lines.update_scalarmappable()
    colours = lines.get_edgecolor()
    assert all(_is(words["compression" if n < 0 else "tension"], rgba) for n, rgba in zip(forces, colours))


def test_the_modes_caption_gives_the_amplitude_the_picture_draws_with_its_colour_scale(drawn, grid, tmp_path):
    """The report says each mode is drawn at a share of the span; the picture's title gives that
    share of this grid's span in mm, and a colour bar says what the colours are."""
    import re

    share = float(re.search(r"drawn at (\d+(?:\.\d+)?) % of\s+the span", _caption("06-analysis/modes.png"))[1])
    modes = np.zeros((3, grid.n_nodes, 6))
    modes[:, :, 2] = np.cos(np.arange(1, 4)[:, None] * grid.nodes[None, :, 0])
    plot_buckling_modes(grid.nodes, grid.edges, modes, np.array([4.2, 5.1, 6.3]), tmp_path / "modes.png")
    figure = drawn[-1]
    drawn_mm = float(re.search(r"largest displacement drawn (\d+) mm", figure._suptitle.get_text())[1])
    span_mm = 1000 * float(np.ptp(grid.nodes, axis=0).max())
    assert drawn_mm == pytest.approx(share / 100 * span_mm, abs=0.5)
    assert any(ax.get_ylabel() == "displacement / the mode's largest" for ax in figure.axes), "a colour bar"
    assert [ax.get_title() for ax in figure.axes if ax.get_title()] == [
        "mode 1: load factor 4.2", "mode 2: load factor 5.1", "mode 3: load factor 6.3"]


def test_the_response_marks_where_each_capacity_was_read(drawn, tmp_path):
    """A limit point is a dot on its curve at the peak; a path stopped at the tolerable deflection
    a square on its curve at its load factor there; the legend names each kind once."""
    t = np.linspace(0, 1, 41)
    peaked = np.column_stack([4 * t * (2 - t), -0.05 * t])          # limit 4.0 at t = 1
    stiffening = np.column_stack([3 * t, -0.02 * t])                # tolerable at 1.5 (t = 0.5)
    plot_response({"perfect": peaked, "mode1+": stiffening, "mode1-": stiffening}, tmp_path / "response.png",
                  worst="mode1+", ends={"perfect": ("limit", 4.0), "mode1+": ("tolerable", 1.5),
                                        "mode1-": ("tolerable", 1.5)})
    ax = drawn[-1].axes[0]
    marks = {line.get_marker(): line.get_xydata() for line in ax.lines if line.get_marker() in ("o", "s")
             and len(line.get_xydata())}
    np.testing.assert_allclose(marks["o"], [[50.0, 4.0]])
    np.testing.assert_allclose(marks["s"], [[10.0, 1.5]])
    labels = ax.get_legend_handles_labels()[1]
    assert labels.count("limit point") == 1 and labels.count("tolerable deflection reached") == 1


def test_pictures_are_palette_pngs_that_look_like_matplotlibs_own(tmp_path):
    """figure_png's palette PNG against matplotlib's own RGBA PNG of the same figure, both read by
    Pillow: the same pixels but for a few levels of colour, black text still black, in under half
    the bytes."""
    import io

    from PIL import Image

    from fabrication.files import PNG_COLOURS, figure_png, save_figure_png
    from workflow.plots._common import pyplot

    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(8, 4))
    x, y = np.meshgrid(np.linspace(-1, 1, 300), np.linspace(-1, 1, 300))
    shown = left.imshow(np.exp(-3 * (x * x + y * y)) + 0.3 * x, cmap="viridis")
    fig.colorbar(shown, ax=left)
    right.contourf(x, y, np.sin(3 * x) * np.cos(2 * y), 30, cmap="magma")
    right.plot([-1, 1], [-1, 1], "r-", lw=2)
    fig.suptitle("a palette picture")
    own = io.BytesIO()
    fig.savefig(own, format="png", dpi=100)
    data = figure_png(fig, dpi=100)
    path = save_figure_png(fig, tmp_path / "picture.png", dpi=100)
    plt.close(fig)
    assert path.read_bytes() == data
    with Image.open(io.BytesIO(data)) as palette, Image.open(own) as reference:
        assert palette.mode == "P" and palette.size == reference.size
        assert len(palette.getcolors(maxcolors=1000)) <= PNG_COLOURS
        ours = np.asarray(palette.convert("RGB"), dtype=float)
        theirs = np.asarray(reference.convert("RGB"), dtype=float)
    error = np.abs(ours - theirs).max(axis=2)
    assert error.mean() < 1.0 and np.percentile(error, 99) <= 8, (error.mean(), np.percentile(error, 99))
    title = theirs.sum(axis=2) == 0  # matplotlib's pure black pixels (text, frame)
    assert title.any() and ours[title].max() <= 12
    assert len(data) < 0.5 * own.getbuffer().nbytes
    _check_png(path)


def test_a_picture_has_the_size_its_dpi_gives_read_from_raw_pixels_or_a_tight_png():
    """figure_png at a number of dots per inch, at the figure's own (dpi='figure', as savefig takes
    it) and with a tight bounding box: Pillow reads the size each gives (the tight one smaller)."""
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from PIL import Image

    from fabrication.files import figure_png

    fig = Figure(figsize=(3, 2), dpi=80)
    FigureCanvasAgg(fig)
    fig.add_subplot().plot([0, 1], [1, 0])
    sizes = {str(kw): Image.open(io.BytesIO(figure_png(fig, **kw))).size
             for kw in ({"dpi": 100}, {"dpi": "figure"}, {"dpi": 100, "bbox_inches": "tight"})}
    assert sizes["{'dpi': 100}"] == (300, 200) and sizes["{'dpi': 'figure'}"] == (240, 160)
    tight = sizes["{'dpi': 100, 'bbox_inches': 'tight'}"]
    assert tight[0] <= 300 and tight[1] <= 200 and tight != (300, 200)


def _strip(length: float = 50.0, depth: float = 5.0):
    """A barrel canopy ``length`` x ``depth`` m, ten times as long as deep (as a station platform's)."""
    from engine.geometry.parametric import grid_triangles
    from engine.mesh import TriMesh

    nx, ny = 60, 6
    x, y = np.meshgrid(np.linspace(0, length, nx + 1), np.linspace(-depth / 2, depth / 2, ny + 1), indexing="ij")
    z = 4.0 + 1.2 * (1 - (2 * y / depth) ** 2)
    return TriMesh(vertices=np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1), faces=grid_triangles(nx, ny))


def _plan_share(figure) -> float:
    """The share of the picture's area that its plans (2-D axes at true scale) take."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    width, height = canvas.get_width_height()
    plans = [ax.get_window_extent() for ax in figure.axes if ax.name == "rectilinear" and ax.get_aspect() == 1.0]
    return sum(b.width * b.height for b in plans) / (width * height)


def test_a_wide_roofs_plans_run_across_the_picture(drawn, tmp_path):
    """A canopy ten times as long as deep: its plans take at least a quarter of each picture, a
    tenth beside a 3-D view (drawn at the sizes for a square roof they took 2-10 %, the rest
    white), and the force picture's legend stays off the plan."""
    from engine.remeshing.field import GuidingField
    from workflow.plots.field import plot_field
    from workflow.plots.shell import plot_principal_forces
    from workflow.plots.surface import plot_surface

    mesh = _strip()
    rng = np.random.default_rng(0)
    forces = -np.abs(rng.normal(1e5, 2e4, (mesh.n_faces, 2)))
    directions = np.tile([1.0, 0.0, 0.0], (mesh.n_faces, 1))
    supports = np.asarray(mesh.boundary_loops[0])
    plot_principal_forces(mesh, forces, directions, tmp_path / "stress.png", support_nodes=supports)
    stress = drawn[-1]
    n = mesh.n_vertices
    field = GuidingField(size=np.linspace(0.5, 1.0, n), anisotropy=np.full(n, 1.5),
                         direction=np.tile([1.0, 0.0, 0.0], (n, 1)), normals=np.tile([0.0, 0.0, 1.0], (n, 1)))
    plot_field(mesh, field, tmp_path / "field.png")
    plot_surface(mesh, supports, tmp_path / "surface.png")
    support = np.zeros(n, dtype=bool)
    support[supports] = True
    grid = quad_grid(mesh, total_length=12.0 * np.sqrt(mesh.area), support_vertices=support)
    plot_gridshell(grid, tmp_path / "grid.png")
    plot_utilisation(grid.nodes, grid.edges, np.linspace(0, 1.2, len(grid.edges)), tmp_path / "utilisation.png")
    shares = {name: _plan_share(figure) for name, figure in
              zip(("stress", "field", "surface", "grid", "utilisation"), drawn)}
    with_3d_view = {"surface", "grid"}  # a 3-D view above the plan takes its row
    assert all(share >= (0.1 if name in with_3d_view else 0.25) for name, share in shares.items()), shares
    plan = next(ax for ax in stress.axes if ax.get_aspect() == 1.0)
    box = plan.get_window_extent()
    legend = plan.get_legend().get_window_extent()
    assert not box.overlaps(legend)


def test_crosses_and_ticks_are_spread_evenly_over_a_fine_mesh():
    """From 250 000 points crowded into one corner and sparse elsewhere: about the asked number, every
    point of the plan within one square's diagonal of a picked one (no gaps), and no two picked
    points closer than a tenth of the spacing (no clumps), where a random choice clumps and gaps."""
    from scipy.spatial import cKDTree

    from workflow.plots._common import spread_sample

    rng = np.random.default_rng(3)
    points = np.r_[rng.random((200_000, 2)) * 2.0, rng.random((50_000, 2)) * 10.0]
    ids, spacing = spread_sample(points, 900, plan_area=100.0)
    assert 800 <= len(ids) <= 1000 and len(np.unique(ids)) == len(ids)
    gaps, _ = cKDTree(points[ids]).query(points)
    assert gaps.max() < np.sqrt(2) * spacing
    closest, _ = cKDTree(points[ids]).query(points[ids], k=2)
    assert closest[:, 1].min() > 0.1 * spacing
    assert np.array_equal(spread_sample(points[:500], 900, plan_area=4.0)[0], np.arange(500))
