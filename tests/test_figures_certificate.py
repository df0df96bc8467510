"""The certificate figure (``certify --figure``): its numbers are the certificate's."""

from __future__ import annotations

import math

import numpy as np

from drip_cert.figures_certificate import (
    _box_outline,
    _convex_hull,
    certificate_figure,
    relative_margin,
)


def test_relative_margin_closed_forms():
    assert relative_margin({"margin": 0.5, "lhs": 0.5, "rhs": 1.0}) == 0.5 / 1.5
    assert relative_margin({"margin": -1.0, "lhs": 2.0, "rhs": 1.0}) == -1.0 / 3.0
    assert relative_margin({"margin": None, "lhs": 1.0, "rhs": 2.0}) is None
    assert relative_margin({"margin": 1.0, "lhs": 1.0, "rhs": math.inf}) is None
    assert relative_margin({"margin": 0.0, "lhs": 0.0, "rhs": 0.0}) is None


def test_a_z_box_is_drawn_as_its_exact_image_in_x():
    """The outline of a box in z = Theta x is the parallelogram Theta^{-1} box: its vertices are
    the images of the box's corners (here a shear, so no corner is inside the hull)."""
    theta_inv = np.array([[1.0, 0.5], [0.0, 1.0]])
    outline = _box_outline([(-1.0, 1.0), (-2.0, 2.0)], theta_inv)
    corners = {(-1.0, -2.0), (-1.0, 2.0), (1.0, -2.0), (1.0, 2.0)}
    images = {tuple(theta_inv @ np.array(c)) for c in corners}
    assert {tuple(p) for p in outline[:-1]} == images
    assert np.array_equal(outline[0], outline[-1])  # closed


def test_convex_hull_drops_interior_points():
    pts = np.array([[0, 0], [2, 0], [2, 2], [0, 2], [1, 1], [1, 0]], dtype=float)
    hull = {tuple(p) for p in _convex_hull(pts)}
    assert hull == {(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)}


def test_figure_is_written_for_a_box_certificate(tmp_path):
    cert = {
        "verdict": "certified",
        "system": {"name": "demo", "n": 2, "states": ["x1", "x2"], "support": [[-1, 1], [-1, 1]]},
        "assumptions": [
            {"id": "DRIP-A2", "status": "holds", "how": "sound", "lhs": -1, "rhs": 0, "margin": 1},
            {"id": "TaSIL", "status": "fails", "how": "estimate", "lhs": 2, "rhs": 1, "margin": -1},
        ],
        "contraction": {
            "expert": {"scope": {"box": [[-2, 2], [-2, 2]]}},
            "invariant_set": {"proved": True, "centre": [0, 0], "radius": 0.5},
        },
        "coordinates": None,
    }
    out = certificate_figure(cert, tmp_path / "c.png")
    assert out.stat().st_size > 10_000  # a rendered two-panel png, not an empty file


def test_training_figure_is_written_atomically(tmp_path):
    """train's figure: losses per method and the held-out gaps against the threshold; the file
    appears whole under its name (no partial file left beside it)."""
    from drip_cert.figures_training import training_figure

    hist = {"tasil": ((0, 10, 20), (1.0, 0.1, 0.01), (1.2, 0.2, 0.02), 20)}
    gaps = {"tasil": np.array([0.01, 0.02, 0.015])}
    out = training_figure(hist, gaps, 0.5, tmp_path / "training.png")
    assert out.stat().st_size > 10_000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["training.png"]
