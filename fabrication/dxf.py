"""The DXF files gridshell writes: one layer table and one set-up for all of them.

Every DXF is R2010 in millimetres ($INSUNITS 4, $MEASUREMENT 1, $DIMLFAC 1). ``LAYERS`` names
each layer with its ACI colour, linetype and what goes on it; a cutting file (a panel, a nesting
sheet) has ``CUTTING_LAYERS``, the plan drawing ``PLAN_LAYERS``. ``new_document`` starts a file
with the layers asked for and ``save_dxf`` (of ``fabrication.files``) writes it with fixed metadata.
``SharedDocument`` writes many files that differ only in their entities (the panels' cutting files).
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from fabrication.files import dxf_bytes, save_dxf, write_bytes_atomic

if TYPE_CHECKING:  # pragma: no cover
    from ezdxf.document import Drawing
    from ezdxf.layouts import Modelspace

__all__ = ["Layer", "LAYERS", "CUTTING_LAYERS", "PLAN_LAYERS", "ENGRAVE_STYLE", "ENGRAVE_FONT",
           "cutting_layers", "new_document", "save_dxf", "SharedDocument"]


@dataclass(frozen=True)
class Layer:
    """A DXF layer: ACI colour, linetype and what goes on it."""

    colour: int
    linetype: str
    description: str


#: Every layer of every DXF gridshell writes, in the order a file lists them: name -> Layer.
LAYERS: dict[str, Layer] = {
    # cutting files: panels/P0001.dxf ..., panels/sheets/SHEET01.dxf ...
    "CUT": Layer(1, "Continuous", "cut outlines of the parts (closed polylines)"),
    "ENGRAVE": Layer(5, "Continuous", "panel ids, engraved in the single-stroke text style"),
    "DRILL": Layer(3, "Continuous", "fixing holes: circles of the hole diameter"),
    "NOTES": Layer(8, "Continuous", "not machined: a panel's note, a sheet's outline and its use"),
    # the plan drawing: drawings/plan.dxf
    "BEAMS": Layer(7, "Continuous", "beams in plan, node to node"),
    "LABELS_NODES": Layer(3, "Continuous", "node ids N0001 ..."),
    "LABELS_BEAMS": Layer(4, "Continuous", "beam ids B0001 ..."),
    "LABELS_PANELS": Layer(6, "Continuous", "panel ids P0001 ..."),
    "LABELS_LEADERS": Layer(8, "Continuous", "leader lines to ids placed away from their part (only when drawn)"),
    "SUPPORTS": Layer(1, "Continuous", "support symbols: a triangle under each supported node"),
    "DIMENSIONS": Layer(2, "Continuous", "overall plan dimensions"),
    "TITLE": Layer(7, "Continuous", "the title block: frame and text"),
}

#: The layers of a cutting file: a panel's DXF and a nesting sheet's.
CUTTING_LAYERS: tuple[str, ...] = ("CUT", "ENGRAVE", "DRILL", "NOTES")
#: The layers of the plan drawing.
PLAN_LAYERS: tuple[str, ...] = ("BEAMS", "LABELS_NODES", "LABELS_BEAMS", "LABELS_PANELS", "LABELS_LEADERS",
                                "SUPPORTS", "DIMENSIONS", "TITLE")

#: Text style of the ids on ENGRAVE: a single-stroke SHX font, as laser and CNC software expect.
ENGRAVE_STYLE = "SINGLESTROKE"
ENGRAVE_FONT = "romans.shx"


#: The application ids ezdxf adds when it first writes a document.
WRITTEN_APPIDS = ("HATCHBACKGROUNDCOLOR", "EZDXF")


def cutting_layers(*, drill: bool) -> tuple[str, ...]:
    """The layers of a cutting file; without ``drill`` (parts without fixing holes) no DRILL layer,
    rather than an empty one."""
    return tuple(name for name in CUTTING_LAYERS if drill or name != "DRILL")


def new_document(layers: Iterable[str], *, setup: bool = False) -> Drawing:
    """A new ezdxf R2010 document in mm with ``layers`` (names of ``LAYERS``, added in the order
    given) and, when ENGRAVE is among them, the engraving text style. ``setup`` adds ezdxf's
    standard linetypes, text and dimension styles (the plan's dimensions need them)."""
    import ezdxf

    doc = ezdxf.new("R2010", setup=setup)
    doc.header["$INSUNITS"] = 4  # mm
    doc.header["$MEASUREMENT"] = 1  # metric
    doc.header["$DIMLFAC"] = 1.0  # dimensions measure drawing units (ezdxf's setup scales by 100)
    names = list(layers)
    for name in names:
        layer = LAYERS[name]
        doc.layers.add(name, color=layer.colour, linetype=layer.linetype)
    if "ENGRAVE" in names:
        doc.styles.add(ENGRAVE_STYLE, font=ENGRAVE_FONT)
    # what ezdxf's first write adds, made now before any entity takes the next handles, so that a
    # SharedDocument's files are those of fresh documents
    for name in WRITTEN_APPIDS:
        if name not in doc.appids:
            doc.appids.new(name)
    doc.ezdxf_metadata()["WRITTEN_BY_EZDXF"] = ""  # its value is set at every write
    return doc


class SharedDocument:
    """Many DXF files that differ only in what their modelspace holds, written from one document:
    its header, tables, blocks and objects are made and written once, and each file adds its own
    entities and its handle seed. The bytes are those of a fresh ``new_document(layers)`` with the
    same entities saved by ``save_dxf``. A fresh document per file spent 16 ms of a panel file's
    18 ms making and writing the parts every file repeats (docs/decisions.md, "Panel files from
    one shared document").

    A drawing that adds anything besides modelspace entities (a layer, a text style, a block) is
    written from a fresh document instead, so nothing is ever left out."""

    _ENTITIES = "  0\nSECTION\n  2\nENTITIES\n"

    def __init__(self, layers: Iterable[str]) -> None:
        self._layers = tuple(layers)
        self._make()

    def _make(self) -> None:
        """The shared document, its file's text split round the handle seed and the entities."""
        self._doc = new_document(self._layers)
        text = dxf_bytes(self._doc).decode(self._doc.output_encoding)
        self._seed = str(self._doc.entitydb.handles)
        head, entities, tail = text.partition(self._ENTITIES)
        before_seed, found, after_seed = head.partition(f"  9\n$HANDSEED\n  5\n{self._seed}\n")
        if not (entities and found and tail.startswith("  0\nENDSEC\n")):
            raise RuntimeError("ezdxf's file layout changed: SharedDocument cannot find the entities or $HANDSEED")
        self._parts = (before_seed, after_seed + self._ENTITIES, tail)
        self._size = len(self._doc.entitydb)

    def save(self, target: str | os.PathLike, draw: Callable[["Modelspace"], object]) -> Path:
        """Draw into the modelspace with ``draw`` and write ``target`` atomically."""
        from ezdxf.lldxf.tagwriter import TagWriter

        doc = self._doc
        msp = doc.modelspace()
        text = None
        try:
            draw(msp)
            if len(doc.entitydb) == self._size + len(msp) and not len(doc.paperspace()):
                stream = io.StringIO()
                msp.entity_space.export_dxf(TagWriter(stream, write_handles=True, dxfversion=doc.dxfversion))
                before_seed, after_seed, tail = self._parts
                text = (f"{before_seed}  9\n$HANDSEED\n  5\n{doc.entitydb.handles}\n{after_seed}"
                        f"{stream.getvalue()}{tail}")
        finally:
            msp.delete_all_entities()
            doc.entitydb.purge()  # deleted entities stay in the database until purged
            doc.entitydb.handles.reset(self._seed)
        if text is None:  # the drawing added more than entities: this file from a fresh document
            self._make()
            fresh = new_document(self._layers)
            draw(fresh.modelspace())
            return save_dxf(fresh, target)
        return write_bytes_atomic(target, doc.encode(text))
