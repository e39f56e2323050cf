"""tools/hance_strength.py: the best share of a JPEG-Hance correction on a left-out scene."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))

import hance_strength  # noqa: E402

from lfstream.models.registry import load_model, spec  # noqa: E402


@pytest.mark.slow
def test_the_best_share_beats_full_strength_and_an_identity_network_changes_nothing():
    from tests.conftest import shared

    shared("hci_star", "cotton")  # skips without the samples
    shipped = hance_strength.strength_on("cotton", load_model("jpeg_hance", "fast", "cpu"), 50)
    # the decoded light field is linear in the strength: s* is at least as good as 1 (rounding aside)
    assert shipped["gain_best_db"] >= shipped["gain_full_db"] - 0.002
    assert shipped["gain_full_db"] > 0.1 and 0.5 < shipped["s_best"] < 2.0, shipped
    identity = hance_strength.strength_on("cotton", spec("jpeg_hance", "fast").build().eval(), 50)
    assert identity["s_best"] == 0.0 and identity["gain_full_db"] == 0.0 and identity["gain_best_db"] == 0.0
