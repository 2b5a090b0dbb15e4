"""An assembly STEP file (AP214) put together from part STEP files, one part at a time.

build123d (OCCT) writes a placed, named solid as a small assembly: a product named by the label
holding one part of the same name, placed by an item-defined transformation. The assembly of many
parts (joints.step: a product "joints" holding J0001, J0002, ...) has the same structure one level
up. Writing it through OCCT means holding every solid and the whole STEP model in one process
(3.9 GiB and 70 s for 500 joints). Here each part's entities are taken from its own file as text,
the file's wrapper product is left out, the rest is renumbered into an id range of its own, and
the assembly writer appends it to the assembly file; the assembly's product, its shape
representation and one next-assembly-usage occurrence with its placement per part are written
around them. A part can so be prepared where it was built (in a worker process), and the writer
holds one part at a time. Entity ids need only be unique within a file (ISO 10303-21 clause 7.3.4),
so the ranges need not be contiguous.
"""

from __future__ import annotations

import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from engine.errors import FabricationError

from .files import atomic_path, file_date

__all__ = ["StepPart", "step_part", "write_step_part", "StepAssemblyWriter", "SCHEMA"]

SCHEMA = "FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));"  # AP214 IS, as OCCT writes it
_ENTITY = re.compile(r"#(\d+)\s*=\s*((?:[^;']|'(?:[^']|'')*')*);")
_STRING = re.compile(r"'(?:[^']|'')*'")
_REFERENCE = re.compile(r"#(\d+)")
_START = re.compile(r"(?m)^#(\d+)\s*=")
_KINDS = re.compile(r"(?m)^#(\d+)\s*=\s*(NEXT_ASSEMBLY_USAGE_OCCURRENCE|CONTEXT_DEPENDENT_SHAPE_REPRESENTATION|"
                    r"APPLICATION_PROTOCOL_DEFINITION|APPLICATION_CONTEXT|PRODUCT_DEFINITION_SHAPE|"
                    r"SHAPE_DEFINITION_REPRESENTATION|PRODUCT_RELATED_PRODUCT_CATEGORY)\s*\(")
_HEAD_IDS = 100  # ids 1..99 are the assembly's own head entities


@dataclass(frozen=True)
class StepPart:
    """The entities of one part, renumbered (``text``), and the ids the assembly refers to: the
    part's product definition, its shape representation, the axis placement in that
    representation (``frame``) and the part's placement in the assembly (``placement``)."""

    name: str
    text: str
    definition: int
    representation: int
    frame: int
    placement: int
    first_id: int
    last_id: int


def _references(body: str) -> list[int]:
    return [int(m) for m in _REFERENCE.findall(_STRING.sub("''", body))]


def step_part(text: str, first_id: int, *, context_id: int = 2) -> StepPart:
    """The part in a STEP file that build123d's ``export_step`` wrote for one placed, named solid
    (see the module docstring), renumbered from ``first_id`` on, with references to the file's
    application context pointing to ``context_id`` (the assembly's).

    Raises FabricationError for a file of another structure (schema, number of parts)."""
    header_end = text.index("ENDSEC;")
    schema = re.search(r"FILE_SCHEMA\s*\(.*?\)\s*;", text[:header_end], re.S)
    if schema is None or " ".join(schema.group(0).split()) != SCHEMA:
        raise FabricationError(f"a part file of another schema: {schema.group(0) if schema else 'none'}")
    data = text[text.index("DATA;", header_end) + 5:text.rindex("ENDSEC;")]
    # where each entity instance starts (OCCT starts each on a line) and the few kinds looked up
    starts = {int(m.group(1)): m.start() for m in _START.finditer(data)}
    by_type: dict[str, list[int]] = {}
    for m in _KINDS.finditer(data):
        by_type.setdefault(m.group(2), []).append(int(m.group(1)))
    cache: dict[int, tuple[int, int, str]] = {}

    def entity(number: int) -> tuple[int, int, str]:
        if number not in cache:
            if number not in starts:
                raise FabricationError(f"entity #{number} not found at the start of a line")
            match = _ENTITY.match(data, starts[number])
            cache[number] = (match.start(), match.end(), match.group(2))
        return cache[number]

    def refs(number: int) -> list[int]:
        return _references(entity(number)[2])

    def one(kind: str) -> int:
        found = by_type.get(kind, [])
        if len(found) != 1:
            raise FabricationError(f"expected one {kind} in a part file, found {len(found)}")
        return found[0]

    occurrence, context = one("NEXT_ASSEMBLY_USAGE_OCCURRENCE"), one("APPLICATION_CONTEXT")
    cdsr = one("CONTEXT_DEPENDENT_SHAPE_REPRESENTATION")
    wrapper, definition = refs(occurrence)[:2]
    relation, placement_shape = refs(cdsr)[:2]
    representation, wrapper_representation, transformation = refs(relation)[:3]
    frame, placement = refs(transformation)[:2]
    formation, definition_context = refs(wrapper)[:2]
    product = refs(formation)[0]
    name = _STRING.search(entity(product)[2]).group(0)[1:-1].replace("''", "'")
    # the wrapper product and everything that is only about it
    hard = {one("APPLICATION_PROTOCOL_DEFINITION"), context, occurrence, cdsr, relation, placement_shape,
            transformation, wrapper, formation, definition_context, product, refs(product)[0], wrapper_representation}
    for number in by_type.get("PRODUCT_DEFINITION_SHAPE", []):
        if refs(number)[:1] == [wrapper]:
            hard.add(number)
            hard.update(n for n in by_type.get("SHAPE_DEFINITION_REPRESENTATION", []) if refs(n)[:1] == [number])
    hard.update(n for n in by_type.get("PRODUCT_RELATED_PRODUCT_CATEGORY", []) if product in refs(n))
    # the wrapper's representation context, its units and uncertainty: written only if a kept entity uses them
    soft = {refs(wrapper_representation)[-1]}
    for number in list(soft):
        soft.update(refs(number))
    for number in list(soft):
        soft.update(refs(number))
    soft -= {frame, placement}

    numbering: dict[int, str] = {}
    next_id = first_id
    for number in starts:
        if number not in hard:
            numbering[number] = f"#{next_id}"
            next_id += 1
    numbering[context] = f"#{context_id}"
    needed: list[int] = []

    def renumber(match: re.Match) -> str:
        old = int(match.group(1))
        if old in soft:
            needed.append(old)
        elif old in hard and old != context:
            raise FabricationError(f"an entity of part {name!r} refers to #{old} of its wrapper product")
        return numbering[old]

    def renumbered(piece: str) -> str:
        # ids outside strings only ('Context #1' is a string): split at the quotes, renumber the
        # pieces outside (even positions) in one pass, put the strings back
        pieces = piece.split("'")
        outside = _REFERENCE.sub(renumber, "\0".join(pieces[0::2])).split("\0")
        pieces[0::2] = outside
        return "'".join(pieces)

    kept, position = [], 0
    for number in sorted(hard | soft, key=lambda n: starts[n]):
        start, end, _ = entity(number)
        kept.append(data[position:start])
        position = end
    kept.append(data[position:])
    body = renumbered("".join(kept)).strip() + "\n"
    extra: list[str] = []
    written: set[int] = set()
    while set(needed) - written:
        number = (set(needed) - written).pop()
        written.add(number)
        start, end, _ = entity(number)
        extra.append(renumbered(data[start:end]).strip() + "\n")
    return StepPart(name=name, text=body + "".join(extra), definition=int(numbering[definition][1:]),
                    representation=int(numbering[representation][1:]), frame=int(numbering[frame][1:]),
                    placement=int(numbering[placement][1:]), first_id=first_id, last_id=next_id - 1)


def write_step_part(part: StepPart, path: Path) -> Path:
    """Store a prepared part (its ids on the first line, then its entities) for ``add_file``."""
    ids = (part.definition, part.representation, part.frame, part.placement, part.first_id, part.last_id)
    with atomic_path(path) as tmp:
        tmp.write_text("\t".join([part.name, *map(str, ids)]) + "\n" + part.text, encoding="utf-8")
    return Path(path)


def _wrapped(items: list[str], per_line: int = 10) -> str:
    return ",\n  ".join(",".join(items[k:k + per_line]) for k in range(0, len(items), per_line))


class StepAssemblyWriter:
    """Writes to an open text file an assembly product named ``name`` holding the parts added
    (in the order added); ``finish`` writes the assembly's entities and the end of the file.

    Parts come from ``step_part`` with ``first_id`` at least ``StepAssemblyWriter.FIRST_ID`` and id
    ranges that do not overlap, directly (``add``) or stored by ``write_step_part`` (``add_file``,
    streamed, not held in memory)."""

    FIRST_ID = _HEAD_IDS

    def __init__(self, file: TextIO, name: str) -> None:
        self._file = file
        self.name = name
        self._parts: list[tuple[str, tuple[int, ...]]] = []
        self._ranges: list[tuple[int, int]] = []
        quoted = name.replace("'", "''")
        stamp = file_date().strftime("%Y-%m-%dT%H:%M:%S")
        file.write("ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('gridshell assembly'),'2;1');\n"
                   f"FILE_NAME('{quoted}','{stamp}',(''),(''),'gridshell fabrication.step_assembly',"
                   f"'Open CASCADE STEP processor (parts)','');\n{SCHEMA}\nENDSEC;\nDATA;\n")

    def _record(self, name: str, ids: tuple[int, ...]) -> None:
        first, last = ids[4], ids[5]
        if first < self.FIRST_ID or any(first <= b and a <= last for a, b in self._ranges):
            raise FabricationError(f"part {name}: entity ids #{first}..#{last} overlap those of another part")
        self._ranges.append((first, last))
        self._parts.append((name, ids))

    def add(self, part: StepPart) -> None:
        self._record(part.name, (part.definition, part.representation, part.frame, part.placement,
                                 part.first_id, part.last_id))
        self._file.write(part.text)

    def add_file(self, path: Path) -> None:
        with open(path, encoding="utf-8") as source:
            fields = source.readline().rstrip("\n").split("\t")
            self._record(fields[0], tuple(int(v) for v in fields[1:7]))
            shutil.copyfileobj(source, self._file, 1 << 20)

    @property
    def next_free_id(self) -> int:
        """The first id above every id written so far."""
        return max([self.FIRST_ID - 1] + [b for _, b in self._ranges]) + 1

    def finish(self, order: list[str] | None = None) -> int:
        """Write the assembly product, one occurrence and placement per part (in the order of the
        names in ``order``, else as added), and the file's end; returns the number of parts."""
        parts = self._parts
        if order is not None:
            by_name = dict(parts)
            if sorted(order) != sorted(by_name) or len(by_name) != len(parts):
                raise FabricationError("the order names other parts than those added")
            parts = [(name, by_name[name]) for name in order]
        n = self.next_free_id
        lines, placements = [], []
        for k, (name, (definition, representation, frame, placement, _, _)) in enumerate(parts, start=1):
            quoted = name.replace("'", "''")
            lines += [f"#{n}=NEXT_ASSEMBLY_USAGE_OCCURRENCE('{k}','{quoted}','',#5,#{definition},$);",
                      f"#{n + 1}=PRODUCT_DEFINITION_SHAPE('Placement','Placement of an item',#{n});",
                      f"#{n + 2}=(REPRESENTATION_RELATIONSHIP('','',#{representation},#10)"
                      f"REPRESENTATION_RELATIONSHIP_WITH_TRANSFORMATION(#{n + 3})SHAPE_REPRESENTATION_RELATIONSHIP());",
                      f"#{n + 3}=ITEM_DEFINED_TRANSFORMATION('','',#{frame},#{placement});",
                      f"#{n + 4}=CONTEXT_DEPENDENT_SHAPE_REPRESENTATION(#{n + 2},#{n + 1});"]
            placements.append(f"#{placement}")
            n += 5
        quoted = self.name.replace("'", "''")
        lines += [
            "#1=APPLICATION_PROTOCOL_DEFINITION('international standard','automotive_design',2000,#2);",
            "#2=APPLICATION_CONTEXT('core data for automotive mechanical design processes');",
            "#3=SHAPE_DEFINITION_REPRESENTATION(#4,#10);",
            "#4=PRODUCT_DEFINITION_SHAPE('','',#5);",
            "#5=PRODUCT_DEFINITION('design','',#6,#9);",
            "#6=PRODUCT_DEFINITION_FORMATION('','',#7);",
            f"#7=PRODUCT('{quoted}','{quoted}','',(#8));",
            "#8=PRODUCT_CONTEXT('',#2,'mechanical');",
            "#9=PRODUCT_DEFINITION_CONTEXT('part definition',#2,'design');",
            f"#10=SHAPE_REPRESENTATION('',({_wrapped(['#11', *placements])}),#15);",
            "#11=AXIS2_PLACEMENT_3D('',#12,#13,#14);",
            "#12=CARTESIAN_POINT('',(0.,0.,0.));",
            "#13=DIRECTION('',(0.,0.,1.));",
            "#14=DIRECTION('',(1.,0.,0.));",
            "#15=(GEOMETRIC_REPRESENTATION_CONTEXT(3)GLOBAL_UNCERTAINTY_ASSIGNED_CONTEXT((#19))"
            "GLOBAL_UNIT_ASSIGNED_CONTEXT((#16,#17,#18))"
            "REPRESENTATION_CONTEXT('Context #1','3D Context with UNIT and UNCERTAINTY'));",
            "#16=(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT(.MILLI.,.METRE.));",
            "#17=(NAMED_UNIT(*)PLANE_ANGLE_UNIT()SI_UNIT($,.RADIAN.));",
            "#18=(NAMED_UNIT(*)SI_UNIT($,.STERADIAN.)SOLID_ANGLE_UNIT());",
            "#19=UNCERTAINTY_MEASURE_WITH_UNIT(LENGTH_MEASURE(1.E-07),#16,'distance_accuracy_value',"
            "'confusion accuracy');",
            "#20=PRODUCT_RELATED_PRODUCT_CATEGORY('part',$,(#7));",
        ]
        self._file.write("\n".join(lines) + "\nENDSEC;\nEND-ISO-10303-21;\n")
        return len(self._parts)
