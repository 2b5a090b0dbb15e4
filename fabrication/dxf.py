"""The DXF files gridshell writes: one layer table and one set-up for all of them.

Every DXF is R2010 in millimetres ($INSUNITS 4, $MEASUREMENT 1, $DIMLFAC 1). ``LAYERS`` names
each layer with its ACI colour, linetype and what goes on it; a cutting file (a panel, a nesting
sheet) has ``CUTTING_LAYERS``, the plan drawing ``PLAN_LAYERS``. ``new_document`` starts a file
with the layers asked for and ``save_dxf`` (of ``fabrication.files``) writes it with fixed metadata.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from fabrication.files import save_dxf

if TYPE_CHECKING:  # pragma: no cover
    from ezdxf.document import Drawing

__all__ = ["Layer", "LAYERS", "CUTTING_LAYERS", "PLAN_LAYERS", "ENGRAVE_STYLE", "ENGRAVE_FONT",
           "cutting_layers", "new_document", "save_dxf"]


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
    return doc
