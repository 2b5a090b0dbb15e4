"""Atomic file output: a file appears complete under its final name, or not at all.

Every writer in gridshell goes through ``atomic_path``: it yields a temporary path in
the same folder, and renames it onto the target only when the block ends without error.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import io
import itertools
import os
import re
import struct
import tempfile
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path

from engine.errors import FabricationError

__all__ = ["atomic_path", "atomic_folder", "write_text_atomic", "write_bytes_atomic", "save_dxf", "dxf_bytes",
           "file_date", "stamp_step", "compact_step_points", "write_assembly_step", "stamp_zip", "stamp_3dm",
           "figure_png", "save_figure_png", "PNG_COLOURS"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success rename it onto ``target``.

    The temporary name keeps the target's suffix (some writers choose the format by it).
    On an exception the temporary file is removed and the target is left untouched.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=suffix or target.suffix,
                                    dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    os.chmod(tmp, 0o666 & ~_umask())
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(target: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``target`` atomically; returns the target path."""
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(target)


def write_bytes_atomic(target: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``target`` atomically; returns the target path."""
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)
    return Path(target)


def atomic_folder(parent: str | os.PathLike, name: str) -> Path:
    """A new empty temporary folder in ``parent`` (mode as for an ordinary new folder).

    The caller fills it and renames it onto its final name when complete.
    """
    path = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=parent))
    os.chmod(path, 0o777 & ~_umask())
    return path


#: Colours of a picture's palette (figure_png).
PNG_COLOURS = 256


def figure_png(fig, **savefig) -> bytes:
    """A matplotlib figure as an 8-bit palette PNG: rendered by Agg (``savefig``'s keywords: dpi,
    bbox_inches...), laid on white, and reduced to PNG_COLOURS colours by median cut without
    dithering. The plots are flat colours, anti-aliased edges and colour maps, so the palette loses
    nothing one sees (on the default job's 84 pictures a channel is off by 0.14 of a level on
    average and by at most 18 of 255 levels at 99.9 % of the pixels), and the file is a third of
    matplotlib's RGBA PNG."""
    from PIL import Image

    rgba = _rendered(fig, savefig)
    white = Image.new("RGBA", rgba.size, (255, 255, 255, 255))
    rgb = Image.alpha_composite(white, rgba).convert("RGB")
    palette = rgb.quantize(colors=PNG_COLOURS, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    out = io.BytesIO()
    palette.save(out, format="PNG")
    return out.getvalue()


def _rendered(fig, savefig: dict):
    """The figure rendered by Agg as an RGBA image: its raw pixels where the size is the figure's
    at the dpi (8 of some 30 ms a picture went to packing and unpacking a PNG), else (a tight
    bounding box) through an unpacked PNG."""
    from PIL import Image

    if savefig.get("bbox_inches") is None:
        dpi = savefig.get("dpi")
        dpi = float(fig.dpi if dpi in (None, "figure") else dpi)
        width, height = (int(v) for v in fig.get_size_inches() * dpi)
        raw = io.BytesIO()
        fig.savefig(raw, format="rgba", **savefig)
        pixels = raw.getvalue()
        if len(pixels) == 4 * width * height:
            return Image.frombuffer("RGBA", (width, height), pixels, "raw", "RGBA", 0, 1)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", **{"pil_kwargs": {"compress_level": 0}, **savefig})
    buffer.seek(0)
    with Image.open(buffer) as image:
        return image.convert("RGBA")


def save_figure_png(fig, target: str | os.PathLike, **savefig) -> Path:
    """``figure_png`` of ``fig`` written atomically to ``target``."""
    return write_bytes_atomic(target, figure_png(fig, **savefig))


def save_dxf(doc, target: str | os.PathLike) -> Path:
    """Save an ezdxf document atomically as ``dxf_bytes`` makes it."""
    return write_bytes_atomic(target, dxf_bytes(doc))


def dxf_bytes(doc) -> bytes:
    """An ezdxf document's file, with fixed metadata and a sorted CLASSES section: ezdxf stamps
    the time and fresh GUIDs ($TDUPDATE, $VERSIONGUID, ...) into every file it writes, and orders
    its classes as a set (by the process's hash seed), so the same drawing gave different bytes
    on every run; here the same drawing gives the same file."""
    from collections import OrderedDict

    import ezdxf

    doc.classes.add_required_classes(doc.dxfversion)
    doc.classes.classes = OrderedDict(sorted(doc.classes.classes.items()))
    doc.ezdxf_metadata()["CREATED_BY_EZDXF"] = f"ezdxf {ezdxf.__version__}"  # stamped with the time at ezdxf.new
    before = ezdxf.options.write_fixed_meta_data_for_testing
    ezdxf.options.write_fixed_meta_data_for_testing = True
    try:
        stream = io.StringIO()
        doc.write(stream)
    finally:
        ezdxf.options.write_fixed_meta_data_for_testing = before
    return doc.encode(stream.getvalue())


def file_date() -> _dt.datetime:
    """The date written into files that carry one (drawings' title blocks, STEP headers, XLSX
    properties, PDF metadata): SOURCE_DATE_EPOCH when set (the reproducible-builds convention),
    else today, at 00:00 UTC. A day, not a time: two runs of the same input on one day give the
    same bytes."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch and epoch.isdigit():
        day = _dt.datetime.fromtimestamp(int(epoch), tz=_dt.timezone.utc).date()
    else:
        day = _dt.datetime.now(tz=_dt.timezone.utc).date()
    return _dt.datetime(day.year, day.month, day.day, tzinfo=_dt.timezone.utc)


_STEP_STAMP = re.compile(rb"FILE_NAME\s*\(\s*'(?:[^']|'')*'\s*,\s*'(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d)")
_STEP_OCCURRENCE = re.compile(rb"(NEXT_ASSEMBLY_USAGE_OCCURRENCE\s*\(\s*')(\d+)(')")


def stamp_step(path: str | os.PathLike) -> None:
    """Make a STEP file the same bytes for the same model: file_date() as its FILE_NAME time stamp
    (the writers put the time of writing there), and its assembly occurrences numbered 1, 2, ...
    in the file's order (OCCT numbers them with a counter of the process, which depends on what
    the process exported before)."""
    path = Path(path)
    data = path.read_bytes()
    match = _STEP_STAMP.search(data, 0, 8192)
    if match:
        stamp = file_date().strftime("%Y-%m-%dT%H:%M:%S").encode()
        data = data[:match.start(1)] + stamp + data[match.end(1):]
    numbers = itertools.count(1)
    data = _STEP_OCCURRENCE.sub(lambda m: m.group(1) + str(next(numbers)).encode() + m.group(3), data)
    path.write_bytes(canonical_step_styles(data))


def write_assembly_step(assembly, target: str | os.PathLike, *, point_decimals: int | None = None) -> Path:
    """Write a cadquery Assembly as an AP214 STEP file (mm, no p-curves, colours and names),
    atomically and stamped (``stamp_step``). Every placed component is named as what it places,
    sub-assemblies too: cadquery's ``Assembly.export`` leaves a sub-assembly's placement unnamed,
    and readers then call the beam "B0001" by its occurrence's number. ``point_decimals``: points
    written to so many places (``compact_step_points``). Returns the path."""
    from cadquery.occ_impl.assembly import toCAF
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.Interface import Interface_Static
    from OCP.STEPCAFControl import STEPCAFControl_Writer
    from OCP.STEPControl import STEPControl_StepModelType
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDF import TDF_Label, TDF_LabelSequence
    from OCP.XCAFDoc import XCAFDoc_DocumentTool, XCAFDoc_ShapeTool
    from OCP.XSControl import XSControl_WorkSession

    _, document = toCAF(assembly, True)
    tool = XCAFDoc_DocumentTool.ShapeTool_s(document.Main())
    shapes = TDF_LabelSequence()
    tool.GetShapes(shapes)
    for i in range(1, shapes.Length() + 1):
        components = TDF_LabelSequence()
        XCAFDoc_ShapeTool.GetComponents_s(shapes.Value(i), components)
        for j in range(1, components.Length() + 1):
            # IsAttribute before FindAttribute: OCP crashes where FindAttribute finds nothing
            component, referred, name = components.Value(j), TDF_Label(), TDataStd_Name()
            if component.IsAttribute(TDataStd_Name.GetID_s()):
                continue
            if XCAFDoc_ShapeTool.GetReferredShape_s(component, referred) and \
                    referred.IsAttribute(TDataStd_Name.GetID_s()) and \
                    referred.FindAttribute(TDataStd_Name.GetID_s(), name):
                TDataStd_Name.Set_s(component, name.Get())
    session = XSControl_WorkSession()  # held here: the writer does not keep it alive
    writer = STEPCAFControl_Writer(session, False)
    writer.SetColorMode(True)
    writer.SetLayerMode(True)
    writer.SetNameMode(True)
    # no p-curves (2D copies of the edges on their faces, which readers rebuild): a third of the bytes
    Interface_Static.SetIVal_s("write.surfacecurve.mode", 0)
    Interface_Static.SetIVal_s("write.precision.mode", 0)
    Interface_Static.SetCVal_s("xstep.cascade.unit", "MM")
    Interface_Static.SetCVal_s("write.step.unit", "MM")
    writer.Transfer(document, STEPControl_StepModelType.STEPControl_AsIs)
    with atomic_path(target) as tmp:
        if writer.Write(str(tmp)) != IFSelect_ReturnStatus.IFSelect_RetDone:
            raise FabricationError(f"OCCT could not write {Path(target).name}")
        stamp_step(tmp)
        if point_decimals is not None:
            compact_step_points(tmp, point_decimals)
    return Path(target)


_STEP_POINT = re.compile(rb"(?m)^(#\d+) = CARTESIAN_POINT\('((?:[^']|'')*)',\(([-+0-9.E,\s]*)\)\s*\);")
_STEP_REAL = re.compile(rb"[-+]?\d+\.\d*(?:E[-+]?\d+)?")


def _short_real(match: re.Match, decimals: int) -> bytes:
    value = round(float(match.group(0)), decimals)
    text = f"{value:.{decimals}f}".rstrip("0")
    return b"0." if text in ("0.", "-0.") else text.encode()


def compact_step_points(path: str | os.PathLike, decimals: int = 8) -> None:
    """Write a STEP file's points (CARTESIAN_POINT, mm) to ``decimals`` places, each on one line.

    OCCT writes 12 decimals, and the poles of the joints' intersection curves are three quarters
    of a joint's bytes. 1e-8 mm is a tenth of OCCT's least tolerance (Precision::Confusion): the
    solids read back valid with the same volume (to 1e-8; 7 places made one mock-up joint invalid
    to BRepCheck, docs/decisions.md)."""
    path = Path(path)
    data = path.read_bytes()
    matches = list(_STEP_POINT.finditer(data))
    # every coordinate of every point shortened in one pass (a callback per number took 35 us a
    # point: 43 ms of a printed socket's 0.8 s), then each point's line put together again
    tokens = [b"".join(m.group(3).split()).split(b",") for m in matches]
    short = _short_reals([t for point in tokens for t in point], decimals)
    pieces, start, k = [], 0, 0
    for match, point in zip(matches, tokens):
        pieces += [data[start:match.start()], match.group(1), b" = CARTESIAN_POINT('", match.group(2), b"',(",
                   b",".join(short[k:k + len(point)]), b"));"]
        start, k = match.end(), k + len(point)
    pieces.append(data[start:])
    path.write_bytes(b"".join(pieces))


def _short_reals(tokens: list[bytes], decimals: int) -> list[bytes]:
    """Each of ``tokens`` (a STEP real, or anything else, kept as it is) to ``decimals`` places,
    trailing zeros dropped: the bytes ``_short_real`` writes for each. Formatting to ``decimals``
    places rounds as ``round`` does (both correctly, from the same binary value), so ``round`` is
    skipped where the rounded value prints back to the same places (under 1e7: its ulp is below
    half the last place)."""
    if not _STEP_REALS.fullmatch(b",".join(tokens)):
        return [_STEP_REAL.sub(lambda m: _short_real(m, decimals), token) for token in tokens]
    out = []
    for value in map(float, tokens):
        text = f"{value if abs(value) < 1e7 else round(value, decimals):.{decimals}f}".rstrip("0")
        out.append(b"0." if text in ("0.", "-0.") else text.encode())
    return out


_STEP_REALS = re.compile(rb"(?:" + _STEP_REAL.pattern + rb")(?:,(?:" + _STEP_REAL.pattern + rb"))*")


_STEP_ENTITY = re.compile(rb"#(\d+)\s*=\s*((?:[^;']|'(?:[^']|'')*')*);")
_STEP_REFERENCE = re.compile(rb"#(\d+)")
_STEP_STRING = re.compile(rb"'(?:[^']|'')*'")
_STEP_STYLES = re.compile(rb"(?m)^#(\d+)\s*=\s*MECHANICAL_DESIGN_GEOMETRIC_PRESENTATION_REPRESENTATION\s*\(")


def canonical_step_styles(data: bytes) -> bytes:
    """The colours of a STEP file in an order that follows from the model alone.

    OCCT writes the presentation (MECHANICAL_DESIGN_GEOMETRIC_PRESENTATION_REPRESENTATION, its
    STYLED_ITEMs, their style chains down to the shared COLOUR_RGBs) last, in the order of a map
    keyed by memory addresses, so the same model gives another order, other ids and another first
    definition of each colour from run to run. Here those entities are numbered again from the
    first of them: the presentations sorted by their content (with the ids of the geometry they
    style, which are the same every run), then depth first through their references. Files whose
    presentation is referenced from before it, or that have none, are returned as they are."""
    first = _STEP_STYLES.search(data)
    end = data.rfind(b"ENDSEC;")
    if first is None or end < first.start():
        return data
    start = int(first.group(1))
    tail = {int(m.group(1)): m.group(2) for m in _STEP_ENTITY.finditer(data, first.start(), end)}
    if min(tail) != start or any(int(r) >= start for r in _STEP_REFERENCE.findall(
            _STEP_STRING.sub(b"''", data[:first.start()]))):
        return data

    # each entity's references into the presentation, read once (strings may hold '#')
    inner = {e: [r for r in map(int, _STEP_REFERENCE.findall(_STEP_STRING.sub(b"''", body))) if r in tail]
             for e, body in tail.items()}
    keys: dict[int, bytes] = {}

    def key(entity: int) -> bytes:
        """The entity's text with every reference into the presentation replaced by its own key."""
        stack = [entity]
        while stack:
            top = stack[-1]
            if top in keys:
                stack.pop()
                continue
            missing = [r for r in inner[top] if r not in keys]
            if missing:
                if len(stack) > len(tail):
                    raise FabricationError("a cycle in the STEP presentation")
                stack.extend(missing)
                continue
            keys[top] = _STEP_REFERENCE.sub(
                lambda m: b"(" + keys[int(m.group(1))] + b")" if int(m.group(1)) in tail else m.group(0), tail[top])
            stack.pop()
        return keys[entity]

    referenced = {r for refs in inner.values() for r in refs}
    try:
        roots = sorted((e for e in tail if e not in referenced), key=key)
    except ValueError:
        return data
    order: list[int] = []
    seen: set[int] = set()
    for root in roots:
        stack = [root]
        while stack:
            entity = stack.pop()
            if entity in seen:
                continue
            seen.add(entity)
            order.append(entity)
            stack.extend(reversed(inner[entity]))
    new_id = {old: start + i for i, old in enumerate(order)}

    def renumber(body: bytes) -> bytes:
        parts = _STEP_STRING.split(body)
        strings = _STEP_STRING.findall(body)
        parts = [_STEP_REFERENCE.sub(lambda m: b"#%d" % new_id.get(int(m.group(1)), int(m.group(1))), part)
                 for part in parts]
        return b"".join(itertools.chain.from_iterable(itertools.zip_longest(parts, strings, fillvalue=b"")))

    lines = b"".join(b"#%d = %s;\n" % (new_id[old], renumber(tail[old])) for old in order)
    return data[:first.start()] + lines + data[end:]


_CORE_TIMES = re.compile(rb"(<dcterms:(?:created|modified)[^>]*>)([^<]*)(</dcterms:)")


def stamp_zip(path: str | os.PathLike) -> None:
    """Rewrite a ZIP container (XLSX) with file_date() as every member's time and as an Office
    document's created and modified times, members and their compression otherwise unchanged
    (zip writers stamp each member with the time of writing)."""
    day = file_date()
    stamp, when = day.timetuple()[:6], day.strftime("%Y-%m-%dT%H:%M:%SZ").encode()
    path = Path(path)
    with zipfile.ZipFile(path) as source:
        members = [(info, source.read(info)) for info in source.infolist()]
    # and the document's own created and modified times (docProps/core.xml)
    members = [(info, _CORE_TIMES.sub(rb"\g<1>" + when + rb"\g<3>", data) if info.filename == "docProps/core.xml"
                else data) for info, data in members]
    tmp = path.with_name(path.name + ".stamp")
    with zipfile.ZipFile(tmp, "w") as target:
        for info, data in members:
            fixed = zipfile.ZipInfo(info.filename, date_time=stamp)
            fixed.compress_type, fixed.external_attr = info.compress_type, info.external_attr
            target.writestr(fixed, data)
    os.replace(tmp, path)


#: openNURBS chunk type codes (opennurbs_3dm.h): the properties table, and in it the revision
#: history (who created and last edited the model, and when); the bits of a code that say the
#: chunk holds an 8-byte value instead of content (the revision history's code has the bit
#: 0x8000 too: its content ends with a CRC-32).
_3DM_PROPERTIES, _3DM_REVISION_HISTORY = 0x10000014, 0x20008021
_3DM_SHORT = 0x80000000


def _3dm_chunks(data: bytes, start: int, end: int, big: bool) -> Iterator[tuple[int, int, int]]:
    """(type code, content start, content length) of the chunks between ``start`` and ``end``."""
    head = "<IQ" if big else "<II"
    size = struct.calcsize(head)
    while start + size <= end:
        code, length = struct.unpack_from(head, data, start)
        length = 0 if code & _3DM_SHORT else length
        yield code, start + size, length
        start += size + length


def _3dm_time(day: _dt.datetime) -> bytes:
    """``day`` as openNURBS writes a time: the C library's struct tm, eight 32-bit integers."""
    t = day.timetuple()
    return struct.pack("<8i", t.tm_sec, t.tm_min, t.tm_hour, t.tm_mday, t.tm_mon - 1, t.tm_year - 1900,
                       (t.tm_wday + 1) % 7, t.tm_yday - 1)


def stamp_3dm(data: bytes) -> bytes:
    """A Rhino .3dm file's bytes with file_date() as the model's created and last edited times.

    openNURBS stamps both with the time of writing (the revision history in the properties table,
    two struct tm under a CRC-32). Write the model to memory (rhino3dm's ``File3dm.Encode``): a
    file written by ``File3dm.Write`` also carries the path it was written to. Bytes whose layout
    is not the one expected are returned as they are."""
    if len(data) < 32 or not data.startswith(b"3D Geometry File Format ") or not data[24:32].strip().isdigit():
        return data
    big = int(data[24:32]) >= 50  # chunk lengths take 8 bytes from version 5 on
    for code, start, length in _3dm_chunks(data, 32, len(data), big):
        if code != _3DM_PROPERTIES:
            continue
        for sub, begin, size in _3dm_chunks(data, start, start + length, big):
            if sub != _3DM_REVISION_HISTORY:
                continue
            body = bytearray(data[begin:begin + size - 4])
            when, at = _3dm_time(file_date()), 1  # after the chunk's version byte
            for _ in range(2):  # created by, created; last edited by, last edited
                (chars,) = struct.unpack_from("<I", body, at)
                at += 4 + 2 * chars  # the name, UTF-16 with its terminating zero
                if at + len(when) > len(body):
                    return data
                body[at:at + len(when)] = when
                at += len(when)
            crc = struct.pack("<I", zlib.crc32(body))
            return data[:begin] + bytes(body) + crc + data[begin + size:]
    return data
