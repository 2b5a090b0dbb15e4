"""The ``gridshell`` command line: a thin shell over the runner and the solver interfaces.

Results and paths go to stdout, progress and messages to stderr. A user mistake
(``GridshellError``) ends with one clear message and exit code 2; ``--debug`` shows the
traceback. Heavy modules are imported inside each command.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from engine.errors import GridshellError, InputError

__all__ = ["main", "build_parser"]

TEMPLATE_NAMES = ("mockup", "cap", "vault", "hypar", "courtyard")


def _template_path(name: str) -> Path:
    import templates

    path = Path(templates.__file__).parent / f"{name}.toml"
    if name not in TEMPLATE_NAMES or not path.is_file():
        raise InputError(f"unknown template {name!r}; templates: {', '.join(TEMPLATE_NAMES)}")
    return path


def _read_json(path: str) -> dict:
    file = Path(path)
    if not file.is_file():
        raise InputError(f"model file {file} does not exist")
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputError(f"{file}: not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise InputError(f"{file}: the model must be a JSON object with nodes, ...")
    return data


def _write_json(data: dict, path: str) -> None:
    from fabrication.files import write_text_atomic

    write_text_atomic(path, json.dumps(data, indent=1))
    print(Path(path).resolve())


def _job_name(project_path: Path) -> str:
    """The default output folder's name for a project: its folder's for a project.toml (as ``init``
    writes it, or a folder given as PROJECT), else the file's stem."""
    path = project_path.resolve()
    if path.is_dir():
        return path.name
    return path.parent.name if path.name == "project.toml" and path.parent.name else path.stem


def _settings(args: argparse.Namespace) -> dict:
    """The dotted project keys and values of ``--set KEY=VALUE`` and ``--cells N``."""
    from .config import parse_setting

    settings = dict(parse_setting(text) for text in args.settings or ())
    if args.cells is not None:
        if args.cells < 1:
            raise InputError(f"--cells {args.cells}: give a number of cells of 1 or more", hint="e.g. --cells 300")
        settings["remesh.n_cells"] = args.cells
    return settings


def _add_settings(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cells", type=int, metavar="N",
                        help="cells of the grid for this run (the project's remesh.n_cells)")
    parser.add_argument("--set", dest="settings", action="append", metavar="KEY=VALUE",
                        help="a project setting for this run, by its dotted key: --set field.max_size_ratio=2, "
                             "--set 'section.diameter=60.3 mm'; repeat for more")


def cmd_run(args: argparse.Namespace) -> int:
    from .config import check_inputs, load_project, project_from_surface, unusual_values
    from .progress import Progress
    from .stages import STAGES

    settings = _settings(args)
    if args.project and args.surface:
        raise InputError("give a PROJECT file or --surface MESH, not both")
    if args.supports and not args.surface:
        raise InputError("--supports applies to --surface MESH only; a project file lists its supports")
    if args.surface_units and not args.surface:
        raise InputError("--surface-units applies to --surface MESH only",
                         hint="a project file gives the unit as [surface] file_units")
    if args.surface_up and not args.surface:
        raise InputError("--surface-up applies to --surface MESH only",
                         hint="a project file gives it as [surface] up_axis")
    if args.only and args.until:
        raise InputError("--only and --until cannot be combined")
    if args.surface:
        project = project_from_surface(args.surface, args.supports or "boundary", args.surface_units or "m",
                                       args.surface_up, settings=settings)
        default_out = Path("out") / Path(args.surface).stem
        project_file = None
    else:
        # no PROJECT: the project.toml of the working folder (as `gridshell init .` writes it), else the mock-up
        here = Path("project.toml")
        given = args.project or (str(here) if here.is_file() else None)
        project_path = Path(given) if given else _template_path("mockup")
        project = load_project(project_path, settings=settings)
        default_out = Path("out") / (_job_name(project_path) if given else "mockup")
        project_file = str(project_path.resolve())
        if given and not args.project:
            print(f"gridshell: running {here.resolve()} (no PROJECT given; where there is no project.toml, "
                  "`gridshell run` runs the mock-up)", file=sys.stderr)
    check_inputs(project, quick_start=bool(args.surface))   # what validate checks, before any stage runs
    for line in unusual_values(project):
        print(f"warning: {line}", file=sys.stderr)
    out_dir = Path(args.out) if args.out else default_out
    progress = Progress(enabled=not args.quiet)
    for note in project.notes:
        progress.message(f"gridshell: {note}")
    progress.message(f"gridshell: {project.project.name} -> {out_dir}")
    names = [s.name for s in STAGES]
    if (project.design.choose == "best" and not args.only
            and (args.until is None or names.index(args.until) >= names.index("analysis"))):
        from .choose import choose_best

        project, _ = choose_best(project, out_dir, project_file=project_file, settings=settings,
                                 say=progress.message)
    from .design_loop import run_with_fitted_grid

    project, summary = run_with_fitted_grid(project, out_dir, STAGES, say=progress.message, until=args.until,
                                            only=args.only, force=args.force, progress=progress,
                                            project_file=project_file)
    if summary.message:
        print(f"stopped: {summary.message}", file=sys.stderr)
    findings = summary.findings
    progress.findings(findings)
    report = out_dir / "report.html"
    print(f"manifest: {summary.manifest_path.resolve()}")
    if report.is_file():
        print(f"report: {report.resolve()}")
    if findings and args.strict:
        print(f"--strict: {len(findings)} failing checks or findings (exit 3)", file=sys.stderr)
        return 3
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    from .config import check_inputs, load_project, unusual_values
    from .stages.surface import check_selections

    project = load_project(args.project, settings=_settings(args))
    across = check_inputs(project)
    supported = check_selections(project)  # the selections match nodes of the surface
    for line in unusual_values(project):
        print(f"warning: {line}", file=sys.stderr)
    for note in project.notes:
        print(f"note: {note}", file=sys.stderr)
    source = project.surface.file or f"template {project.surface.template}"
    if across is not None:
        source += f", {across:.3g} m across"
    print(f"{args.project}: valid ({project.project.name}; surface {source}; "
          f"{len(project.supports)} support selection(s), {supported} supported nodes; "
          f"{len(project.loads.cases)} load case(s))")
    return 0


def cmd_init(args: argparse.Namespace) -> int:
    from fabrication.files import write_text_atomic

    source = _template_path(args.template)
    target = Path(args.dir) / "project.toml"
    if target.exists() and not args.force:
        raise InputError(f"{target} already exists", hint="use --force to overwrite it")
    write_text_atomic(target, source.read_text(encoding="utf-8"))
    print(target.resolve())
    print(f"next: gridshell run {target}", file=sys.stderr)
    return 0


def cmd_shell(args: argparse.Namespace) -> int:
    from .solver_json import solve_shell_json

    _write_json(solve_shell_json(_read_json(args.model)), args.out)
    return 0


def cmd_frame(args: argparse.Namespace) -> int:
    from .solver_json import solve_frame_json

    control = None
    if args.control:
        node, dof = args.control
        try:
            control = (int(node), dof)
        except ValueError:
            raise InputError(f"--control NODE DOF: NODE must be a 0-based node id, got {node!r}") from None
        if dof not in ("ux", "uy", "uz", "rx", "ry", "rz"):
            raise InputError(f"--control NODE DOF: DOF must be one of ux, uy, uz, rx, ry, rz, got {dof!r}")
    result = solve_frame_json(_read_json(args.model), analysis=args.analysis, modes=args.modes,
                              control=control, max_load_factor=args.max_load_factor)
    _write_json(result, args.out)
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from .compare import run_compare

    return run_compare(args)


def cmd_sweep(args: argparse.Namespace) -> int:
    from .sweep import cmd_sweep as sweep

    return sweep(args)


#: The loggers of the product's packages (each module logs to a child of one of them).
PACKAGE_LOGGERS = ("engine", "fabrication", "workflow")


def log_to_stderr(level: int) -> None:
    """Send the product's log records at ``level`` and above to stderr, with their time and module."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s: %(message)s", datefmt="%H:%M:%S"))
    for name in PACKAGE_LOGGERS:
        logger = logging.getLogger(name)
        logger.setLevel(level)
        logger.addHandler(handler)


def build_parser() -> argparse.ArgumentParser:
    from .runner import product_version

    parser = argparse.ArgumentParser(prog="gridshell", description="Statics-aware Voronoi grid-shells: "
                                     "from a free-form surface to shop drawings.")
    parser.add_argument("--version", action="version", version=f"gridshell {product_version()}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log what the run does to stderr: why each stage runs or is cached, the solvers "
                             "and paths (-vv: every step, with times)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="run a project (default: ./project.toml, else the 2.4 m mock-up template)")
    run.add_argument("project", nargs="?", help="project file (TOML)")
    run.add_argument("--surface", metavar="MESH", help="quick start from a mesh file (OBJ, PLY, STL, OFF, 3DM)")
    run.add_argument("--supports", choices=("boundary", "flagged"), help="supports for --surface (default boundary)")
    run.add_argument("--surface-units", choices=("m", "cm", "mm", "in", "ft"),
                     help="the unit the --surface mesh was modelled in (default m)")
    run.add_argument("--surface-up", choices=("z", "y", "x", "-z", "-y", "-x"),
                     help="the --surface mesh's up axis (default z; Blender, SketchUp and glTF exports: y)")
    _add_settings(run)
    run.add_argument("--out", metavar="DIR", help="output folder (default out/NAME)")
    run.add_argument("--until", metavar="STAGE", help="stop after this stage")
    run.add_argument("--only", metavar="STAGE", help="run only this stage (earlier results must exist)")
    run.add_argument("--force", action="store_true", help="ignore cached results")
    run.add_argument("--quiet", action="store_true", help="no progress output")
    run.add_argument("--strict", action="store_true",
                     help="exit 3 when a check fails or a part cannot be built (findings); default exit 0")
    run.set_defaults(func=cmd_run)

    validate = sub.add_parser("validate", help="check a project file")
    validate.add_argument("project")
    _add_settings(validate)
    validate.set_defaults(func=cmd_validate)

    init = sub.add_parser("init", help="write a starter project file")
    init.add_argument("dir")
    init.add_argument("--template", default="mockup", help=f"one of {', '.join(TEMPLATE_NAMES)}")
    init.add_argument("--force", action="store_true", help="overwrite an existing project.toml")
    init.set_defaults(func=cmd_init)

    shell = sub.add_parser("shell", help="solve a shell model given as JSON (see docs/formats.md)")
    shell.add_argument("model")
    shell.add_argument("--out", required=True, metavar="RESULT.json")
    shell.set_defaults(func=cmd_shell)

    frame = sub.add_parser("frame", help="solve a frame model given as JSON (see docs/formats.md)")
    frame.add_argument("model")
    frame.add_argument("--analysis", choices=("linear", "buckling", "nonlinear"), default="linear")
    frame.add_argument("--modes", type=int, default=6)
    frame.add_argument("--control", nargs=2, metavar=("NODE", "DOF"))
    frame.add_argument("--max-load-factor", type=float, dest="max_load_factor")
    frame.add_argument("--out", required=True, metavar="RESULT.json")
    frame.set_defaults(func=cmd_frame)

    compare = sub.add_parser("compare", help="compare the Voronoi grid with lattices and an isotropic control "
                                             "of equal length")
    compare.add_argument("project")
    compare.add_argument("--out", metavar="DIR")
    compare.add_argument("--quiet", action="store_true")
    compare.add_argument("--grids", metavar="LIST",
                         help="comma list of the rows: triangular,quad,quad45,statics_quad,isotropic,voronoi "
                              "(default: all)")
    compare.add_argument("--size-sections", action="store_true",
                         help="size each grid's tubes as [design] size_sections does, and compare their masses")
    compare.set_defaults(func=cmd_compare)

    sweep = sub.add_parser("sweep", help="run the points of a parameter grid on Dask (see the README)")
    sweep.add_argument("sweep", metavar="SWEEP.toml")
    sweep.add_argument("--out", metavar="DIR", help="output folder (default out/SWEEP)")
    sweep.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://HOST:8786 "
                       "(default: a local cluster)")
    sweep.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: the cores)")
    sweep.add_argument("--quiet", action="store_true", help="no progress output")
    sweep.set_defaults(func=cmd_sweep)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.verbose:
        log_to_stderr(logging.DEBUG if args.verbose > 1 else logging.INFO)
    try:
        return int(args.func(args) or 0)
    except GridshellError as exc:
        if args.debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
