"""What the stub writes over its picture: a name and posture label above each soldier, the view's caption,
and the keys (``?``).

A label hangs above the soldier's head, projected with the frame's own view-projection matrix; labels
behind the camera, off the picture or farther than :data:`LABEL_RANGE_M` are left out, and so is a label
that would cover a nearer soldier's (the current soldier's always shows); at most :data:`MAX_LABELS`.
Text is drawn with Pillow on the finished frame (each text once, cached), so every back end gets the same.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from PIL import ImageFont

    Font = ImageFont.FreeTypeFont | ImageFont.ImageFont

LABEL_RANGE_M = 60.0
MAX_LABELS = 24  # the nearest ones, so a crowd is not a wall of text
CURRENT = (255, 230, 90)  # the current soldier's label
TEXT = (255, 255, 255)
BOX = (0, 0, 0, 150)


@dataclass(frozen=True)
class Label:
    """``name`` and ``posture`` lines above world point ``anchor`` (Performer metres)."""

    name: str
    posture: str
    anchor: tuple[float, float, float]
    current: bool = False


@dataclass
class Overlay:
    labels: list[Label] = field(default_factory=list)
    caption: str = ""
    help: tuple[tuple[str, str], ...] = ()  # the keys (key, what it does), shown while not empty

    def draw(self, frame: np.ndarray, viewproj: np.ndarray) -> np.ndarray:
        """``frame`` (h, w, 3) uint8 with the overlay on it (a new array). Each text is drawn once into a
        cached patch and blended in with numpy, so a hundred labels cost a few milliseconds."""
        out = np.array(frame, np.uint8, copy=True)
        for left, top, patch in self.patches(frame.shape[1], frame.shape[0], viewproj):
            _blend(out, patch, left, top)
        return out

    def rgba(self, width: int, height: int, viewproj: np.ndarray) -> np.ndarray:
        """The overlay alone, ``(height, width, 4)`` uint8 premultiplied RGBA on transparent, top row first
        (the window blends it over pyrender's picture)."""
        out = np.zeros((height, width, 4), np.uint8)
        for left, top, patch in self.patches(width, height, viewproj):
            _blend(out, patch, left, top)
        return out

    def patches(self, w: int, h: int, viewproj: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
        """``(left, top, RGBA patch)`` in drawing order: labels far to near, the caption, the keys."""
        size = max(10, h // 48)
        placed: list[tuple[int, int, np.ndarray]] = []
        taken: list[tuple[int, int, int, int]] = []
        for label, (x, y) in reversed(project_labels(self.labels, viewproj, w, h)):  # nearest first
            patch = _patch(f"{label.name}\n{label.posture}", CURRENT if label.current else TEXT, size, True)
            left, top = int(x - patch.shape[1] / 2), int(y - patch.shape[0] - 4)
            rect = (left, top, left + patch.shape[1], top + patch.shape[0])
            if label.current or not any(_overlap(rect, r) for r in taken):
                placed.append((left, top, patch))
                taken.append(rect)
            if len(placed) >= MAX_LABELS:
                break
        placed.reverse()
        if self.caption:
            placed.append((6, 4, _patch(self.caption + "   (? keys)", TEXT, max(11, h // 40), False)))
        if self.help:
            placed.append((6, 8 + h // 16, _table_patch(self.help, TEXT, max(10, h // 52))))
        return placed


def project_labels(
    labels: list[Label], viewproj: np.ndarray, width: int, height: int
) -> list[tuple[Label, tuple[float, float]]]:
    """The labels in the picture with their pixel positions, farthest first."""
    if not labels:
        return []
    p = np.array([lb.anchor for lb in labels], np.float64)
    clip = np.column_stack([p, np.ones(len(p))]) @ np.asarray(viewproj).T
    w = clip[:, 3]
    ok = w > 1e-6
    ndc = clip[:, :2] / np.where(ok, w, 1.0)[:, None]
    x = (ndc[:, 0] + 1) / 2 * width
    y = (1 - ndc[:, 1]) / 2 * height
    ok &= (x >= 0) & (x < width) & (y >= 0) & (y < height) & (w < LABEL_RANGE_M)
    order = [int(i) for i in np.argsort(-w) if ok[i]]
    return [(labels[i], (float(x[i]), float(y[i]))) for i in order]


@lru_cache(maxsize=8)
def _font(size: int) -> Font:
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError):  # Pillow without FreeType: the fixed bitmap font
        return ImageFont.load_default()


@lru_cache(maxsize=1024)
def _patch(text: str, colour: tuple[int, int, int], size: int, centred: bool) -> np.ndarray:
    """(h, w, 4) uint8 RGBA: ``text`` on a translucent dark box."""
    from PIL import Image, ImageDraw

    font = _font(size)
    align = "center" if centred else "left"
    box = ImageDraw.Draw(Image.new("RGBA", (1, 1))).multiline_textbbox((0, 0), text, font=font, align=align)
    pad = 4
    size_px = (int(np.ceil(box[2] - box[0])) + 2 * pad, int(np.ceil(box[3] - box[1])) + 2 * pad)
    image = Image.new("RGBA", size_px, BOX)
    ImageDraw.Draw(image).multiline_text(
        (pad - box[0], pad - box[1]), text, font=font, fill=(*colour, 255), align=align
    )
    return np.asarray(image)


@lru_cache(maxsize=8)
def _table_patch(rows: tuple[tuple[str, str], ...], colour: tuple[int, int, int], size: int) -> np.ndarray:
    """(h, w, 4) uint8 RGBA: two left-aligned columns on a translucent dark box."""
    from PIL import Image, ImageDraw

    font = _font(size)
    left, right = "\n".join(k for k, _ in rows), "\n".join(t for _, t in rows)
    measure = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    a = measure.multiline_textbbox((0, 0), left, font=font)
    b = measure.multiline_textbbox((0, 0), right, font=font)
    pad, gap = 5, 14
    width = int(np.ceil(a[2] - a[0] + gap + b[2] - b[0])) + 2 * pad
    height = int(np.ceil(max(a[3], b[3]) - min(a[1], b[1]))) + 2 * pad
    image = Image.new("RGBA", (width, height), BOX)
    draw = ImageDraw.Draw(image)
    top = pad - min(a[1], b[1])
    draw.multiline_text((pad - a[0], top), left, font=font, fill=(*colour, 255))
    draw.multiline_text((pad + a[2] - a[0] + gap - b[0], top), right, font=font, fill=(*colour, 255))
    return np.asarray(image)


def _overlap(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _blend(frame: np.ndarray, patch: np.ndarray, left: int, top: int) -> None:
    """Alpha-blend an RGBA ``patch`` over ``frame`` at ``(left, top)``, clipped to it. An RGBA ``frame`` is
    premultiplied: its alpha becomes ``a + old (1 - a)``."""
    h, w = frame.shape[:2]
    x0, y0 = max(left, 0), max(top, 0)
    x1, y1 = min(left + patch.shape[1], w), min(top + patch.shape[0], h)
    if x0 >= x1 or y0 >= y1:
        return
    p = patch[y0 - top : y1 - top, x0 - left : x1 - left]
    a = p[..., 3:].astype(np.uint16)
    region = frame[y0:y1, x0:x1]
    old = region.astype(np.uint16)
    region[..., :3] = (p[..., :3] * a + old[..., :3] * (255 - a) + 127) // 255
    if region.shape[2] == 4:
        region[..., 3] = a[..., 0] + (old[..., 3] * (255 - a[..., 0]) + 127) // 255
