"""What the printed page lays out beyond its content area: the PDF build fails on it.

weasyprint lays a table that is wider than the page out at its full width and prints what passes
the right margin off the paper, silently. :func:`overflows` walks the layout tree of every page
and lists each box whose right edge passes the page's content area (the element, its nearest
ancestor with an id, by how much); :func:`check_fits` raises :class:`PageOverflowError` naming
them, so that a table that does not fit is a failed build, not a page that loses columns.
"""

from __future__ import annotations

from dataclasses import dataclass

TOLERANCE_PX = 1.0
"""Layout round-off allowed beyond the content edge (CSS px, 1/96 in)."""


class PageOverflowError(RuntimeError):
    """A printed box runs past the right edge of the page's content area."""


@dataclass(frozen=True)
class Overflow:
    page: int  # 1-based
    tag: str
    anchor: str  # id of the element or of its nearest ancestor with one ("" if none)
    excess_px: float  # how far the box's right margin edge passes the content edge

    def describe(self) -> str:
        where = f"#{self.anchor}" if self.anchor else "an element without id"
        return f"page {self.page}: <{self.tag}> in {where} passes the right margin by {self.excess_px:.0f} px"


def _element_id(box) -> str:
    el = getattr(box, "element", None)
    return el.get("id", "") if el is not None and hasattr(el, "get") else ""


def _right_edge(box) -> float | None:
    x = getattr(box, "position_x", None)
    try:
        w = box.margin_width()
    except (AttributeError, TypeError):
        return None
    return None if x is None or w is None else float(x) + float(w)


def page_overflows(page_box, number: int, tolerance: float = TOLERANCE_PX) -> list[Overflow]:
    """The outermost boxes of one page that pass its content area on the right (a box inside an
    overflowing one is not listed again)."""
    right = float(page_box.content_box_x()) + float(page_box.width)
    found: list[Overflow] = []

    def walk(box, anchor: str) -> None:
        anchor = _element_id(box) or anchor
        edge = _right_edge(box)
        if edge is not None and edge > right + tolerance:
            found.append(Overflow(number, str(getattr(box, "element_tag", "") or type(box).__name__), anchor,
                                  edge - right))
            return
        for child in getattr(box, "children", None) or ():
            walk(child, anchor)

    for child in getattr(page_box, "children", None) or ():
        if type(child).__name__ == "MarginBox":  # running headers and footers live in the margin
            continue
        walk(child, "")
    return found


def overflows(document) -> list[Overflow]:
    """Every overflow of a rendered weasyprint ``Document``."""
    out: list[Overflow] = []
    for i, page in enumerate(document.pages, start=1):
        root = getattr(page, "_page_box", None)
        if root is not None:
            out += page_overflows(root, i)
    return out


def check_fits(document) -> None:
    """Raise :class:`PageOverflowError` listing (up to 8) boxes that do not fit their page."""
    bad = overflows(document)
    if bad:
        more = f" (and {len(bad) - 8} more)" if len(bad) > 8 else ""
        raise PageOverflowError("the printed report is wider than its page: "
                                + "; ".join(o.describe() for o in bad[:8]) + more)
