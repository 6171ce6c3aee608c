"""The peer interface: proposals checked, and the peers' requests combined."""

import numpy as np
import pytest

from trackers.peers import (
    PeerError,
    PeerProposal,
    PointTrackState,
    PointTrackView,
    ResolutionCell,
    check_proposal,
    combine_directives,
)
from trackers.types import Scan


def view_of(positions, time=1.0):
    n = len(positions)
    x = np.zeros((n, 5))
    x[:, :2] = np.reshape(positions, (n, 2))
    return PointTrackView(
        time=time,
        ids=tuple(f"T{i + 1}" for i in range(n)),
        x=x,
        P=np.tile(np.eye(5), (n, 1, 1)),
        score=np.zeros(n),
        hits=np.ones(n),
        confirmed=np.ones(n, dtype=bool),
        created=np.zeros(n),
        updated=np.zeros(n),
    )


def scan_of(n, time=1.0):
    return Scan("r", time, np.zeros((n, 2)), np.tile(np.eye(2), (n, 1, 1)))


def handed(tid, time=1.0, **kw):
    args = dict(x=np.zeros(5), P=np.eye(5), score=3.0, hits=3, confirmed=True, created=0.0)
    args.update(kw)
    return PointTrackState(tid, time, updated=time, **args)


def none(n):
    return np.zeros(n, dtype=bool)


def test_resolution_cell_contains_the_points_of_its_ellipse():
    cell = ResolutionCell(center=[10.0, 0.0], matrix=np.diag([100.0, 4.0]), pd=0.5)
    inside = cell.contains(np.array([[19.0, 0.0], [10.0, 1.9], [10.0, 2.1], [21.0, 0.0]]))
    assert inside.tolist() == [True, True, False, False]


def test_the_lowest_detection_probability_holds_and_cells_apply_by_predicted_position():
    view = view_of([[0, 0], [100, 0], [1000, 0]])
    a = PeerProposal(none(0), pd={"T1": 0.6, "T2": 0.4})
    b = PeerProposal(none(0), pd={"T1": 0.8}, cells=(ResolutionCell([100, 0], np.eye(2), 0.2),))
    d = combine_directives(("a", "b"), (a, b), view)
    assert dict(d.pd) == {"T1": 0.6, "T2": 0.2}


def test_a_track_taken_by_two_peers_names_the_second():
    view = view_of([[0, 0]])
    a, b = PeerProposal(none(0), take=("T1",)), PeerProposal(none(0), take=("T1",))
    with pytest.raises(PeerError, match=r"peer 'b'.*already taken by peer 'a'"):
        combine_directives(("a", "b"), (a, b), view)


def test_an_id_handed_back_by_two_peers_names_the_second():
    view = view_of([])
    a, b = (
        PeerProposal(none(0), hand_back=(handed("X1"),)),
        PeerProposal(none(0), hand_back=(handed("X1"),)),
    )
    with pytest.raises(PeerError, match="peer 'b'"):
        combine_directives(("a", "b"), (a, b), view)


@pytest.mark.parametrize(
    ("proposal", "text"),
    [
        (PeerProposal(none(2), take=("T1", "T1")), "twice"),
        (PeerProposal(none(2), hand_back=(handed("X", time=0.5),)), "scan's time"),
        (PeerProposal(none(2), hand_back=(handed("X", P=-np.eye(5)),)), "positive definite"),
        (PeerProposal(none(2), hand_back=(handed("X", score=float("nan")),)), "non-finite"),
        (PeerProposal(none(2), cells=(ResolutionCell([0, 0], -np.eye(2), 0.5),)), "matrix"),
        (PeerProposal(none(2), cells=(ResolutionCell([0, 0], np.eye(2), 0.0),)), "pd"),
        (PeerProposal(none(2), pd={"T1": "high"}), "(0, 1]"),
    ],
)
def test_ill_formed_proposals(proposal, text):
    with pytest.raises(PeerError) as err:
        check_proposal("formation", proposal, scan_of(2), view_of([[0, 0]]))
    assert err.value.kind == "formation" and text in err.value.detail


def test_a_well_formed_proposal_passes():
    prop = PeerProposal(
        np.array([True, False]),
        pd={"T1": 0.5},
        cells=(ResolutionCell([0, 0], np.eye(2), 0.3),),
        take=("T1",),
        hand_back=(handed("F7"),),
    )
    check_proposal("formation", prop, scan_of(2), view_of([[0, 0]]))


def test_hand_over_records_are_read_only_copies():
    x = np.zeros(5)
    st = handed("X", x=x)
    x[0] = 5.0
    assert st.x[0] == 0.0
    with pytest.raises(ValueError):
        st.x[0] = 1.0
