"""Link impairments (bridge.media.impairments): a partition takes every reception across its groups and none within
one; Gilbert-Elliott loss comes in bursts of the configured mean length and share, the same for the same seed; on the
2.4 GHz channel a partition silences the frames between groups while the rest are decoded as before."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from bridge.media.impairments import Impairments
from tests.media.test_radio_medium import CALM, MS, frame, medium, run


def test_a_partition_cuts_across_groups_only_while_it_lasts() -> None:
    imp = Impairments(1, "radio")
    imp.partition(10, 20, [[0, 1], [2, 3]])
    dsts = np.array([1, 2, 3, 4])
    assert imp.lost(5, 0, dsts).tolist() == [False, False, False, False]  # before
    assert imp.lost(10, 0, dsts).tolist() == [False, True, True, False]  # robot 4 is in no group: hears all
    assert imp.lost(15, 4, np.array([0, 2])).tolist() == [False, False]
    assert imp.lost(20, 0, dsts).tolist() == [False, False, False, False]  # over
    assert imp.report()["partitioned"] == 2
    with pytest.raises(ValueError, match="no robot in two"):
        imp.partition(0, None, [[0, 1], [1, 2]])
    with pytest.raises(ValueError, match="two or more"):
        imp.partition(0, None, [[0, 1]])


def test_gilbert_elliott_loss_has_the_configured_bursts_and_share() -> None:
    p_gb, p_bg = 0.02, 0.25  # bad 7.4 % of the time, in bursts of 4 frames on average
    imp = Impairments(7, "radio")
    imp.burst_loss(0, None, p_gb, p_bg)
    lost = [bool(imp.lost(k, 0, np.array([1]))[0]) for k in range(200_000)]
    share = sum(lost) / len(lost)
    runs = [len(list(g)) for k, g in itertools.groupby(lost) if k]
    assert share == pytest.approx(p_gb / (p_gb + p_bg), rel=0.05)
    assert np.mean(runs) == pytest.approx(1 / p_bg, rel=0.05)
    again = Impairments(7, "radio")
    again.burst_loss(0, None, p_gb, p_bg)
    assert [bool(again.lost(k, 0, np.array([1]))[0]) for k in range(2000)] == lost[:2000]  # same seed, same losses
    with pytest.raises(ValueError):
        imp.burst_loss(0, None, 0.0, 0.5)


def test_burst_loss_on_some_robots_leaves_the_other_links_alone() -> None:
    imp = Impairments(3, "radio")
    imp.burst_loss(0, None, 1.0, 0.01, robots=[2])  # every link of robot 2 goes bad at once
    assert imp.lost(0, 0, np.array([1, 2])).tolist() == [False, True]
    assert imp.lost(1, 2, np.array([0, 1])).tolist() == [True, True]
    assert imp.lost(2, 1, np.array([0])).tolist() == [False]


def test_a_partition_on_the_air_silences_only_the_frames_between_groups() -> None:
    m, _ = medium([(0, 0), (2, 0), (0, 2), (2, 2)], **CALM)
    m.impairments.partition(0, None, [[0, 1], [2, 3]])
    m.submit(0, 5 * MS, frame(1, 0))  # broadcast from group A
    m.submit(3, 60 * MS, frame(2, 3))  # broadcast from group B
    rx = sorted((e["frame"]["src16"] - 1, r) for _, r, e in run(m, 200 * MS) if e["ev"] == "rx")
    assert rx == [(0, 1), (3, 2)]
    assert m.impairments.report()["partitioned"] == 4
