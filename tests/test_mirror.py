"""The mirror test (matching/mirror.py; method.md §2, "Mirror images") on glyphs of the fonts
matplotlib ships, 200 nodes: a cross-font pair mirrored is said, a near-symmetric one and
one whose first pose is a wrong turn are not (benchmarks/mirror.py measures the rule)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from modalmorph import match
from modalmorph.core.shape import resample
from modalmorph.datasets import load_heart
from modalmorph.matching.mirror import MIRROR, MIRROR_SUSPECT, mirror_gap

TURN = np.radians(34.0)  # the turned poses of benchmarks/mirror.py


def outline(ch: str, font: str, n: int = 200) -> np.ndarray:
    """The glyph's outer contour (largest area), ``n`` nodes by arc length."""
    import matplotlib
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    path = os.path.join(matplotlib.get_data_path(), "fonts", "ttf", f"{font}.ttf")
    polys = TextPath((0, 0), ch, size=100, prop=FontProperties(fname=path)).to_polygons(
        closed_only=True)
    p = max(polys, key=lambda q: abs(np.sum(q[:, 0] * np.roll(q[:, 1], -1)
                                            - np.roll(q[:, 0], -1) * q[:, 1])))
    return resample(p[:-1], n)


def posed(p: np.ndarray, flip=(1.0, 1.0), turn: float = 0.0) -> np.ndarray:
    """``p`` mirrored by ``flip`` about its centroid, then turned by ``turn`` radians."""
    c = p.mean(axis=0)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    return c + ((p - c) * flip) @ rot.T


@pytest.mark.parametrize("ch, flip, turn", [("R", (1.0, -1.0), 0.0), ("F", (-1.0, 1.0), 0.0),
                                            ("b", (-1.0, 1.0), TURN)])
def test_a_cross_font_mirror_image_is_said(ch, flip, turn):
    """STIX -> cmr10 onto the target mirrored (an upside-down 'R', a mirrored 'F', a 'b'
    mirrored and turned: a 'd'): said, the ratio over MIRROR; as given, nothing."""
    a, b = outline(ch, "STIXGeneral"), outline(ch, "cmr10")
    assert match(a, b).mirror is None
    found = match(a, posed(b, flip, turn))
    assert found.mirror is not None and found.mirror > MIRROR


@pytest.mark.parametrize("ch", "OHA08")
def test_a_near_symmetric_mirror_image_is_not_said(ch):
    """Near-symmetric outlines fit alike both ways: their mirror images (x, and y turned)
    across fonts are not called mirrored, nor is the bundled heart's."""
    a, b = outline(ch, "STIXGeneral"), outline(ch, "cmr10")
    for flip, turn in (((-1.0, 1.0), 0.0), ((1.0, -1.0), TURN)):
        assert match(a, posed(b, flip, turn)).mirror is None
    ed, es = load_heart("diastole"), load_heart("systole")
    assert match(ed, posed(es, (-1.0, 1.0), TURN)).mirror is None


def test_a_wrong_first_pose_is_not_a_mirror_image():
    """A DejaVu Sans Mono '0' onto STIX's turned 150 deg: rotation="auto" takes a wrong
    turn whose gap is over MIRROR_SUSPECT and over MIRROR times the reflected source's
    (the former rule said mirrored); in any pose the source as given fits as well as
    reflected, so nothing is said. (Turned 34 deg, the case until session 16, its turn is
    now found.)"""
    a = outline("0", "DejaVuSansMono")
    b = posed(outline("0", "STIXGeneral"), turn=np.radians(150.0))
    found = match(a, b)
    g0 = mirror_gap(a, b, found.similarity)
    g1 = mirror_gap(a * [-1.0, 1.0], b, match(a * [-1.0, 1.0], b, rotation="free").similarity)
    assert g0 > MIRROR_SUSPECT and g0 > MIRROR * g1
    assert found.mirror is None
