"""Giving way to the other robots through their published intents."""

from __future__ import annotations

import math

import numpy as np

from agents.follower import FollowState, keep_clear
from agents.peers import gives_way, intent_centres, intent_points, path_intent, rim_points
from fleet.params import AgentParams
from planners.dwa import DWAParams, rollout

AGENT = AgentParams()
DWA = DWAParams()


def test_robots_give_way_in_natural_id_order() -> None:
    assert gives_way("robot-1", "robot-0") and not gives_way("robot-0", "robot-1")
    assert gives_way("robot-10", "robot-2")  # not string order
    assert not gives_way("robot-3", "robot-3")


def test_intent_points_follow_the_held_command() -> None:
    pts = intent_points((1.0, 2.0, math.pi / 2), 0.5, 0.0, 10.0, 2.0)
    assert pts.shape == (11, 3)
    assert np.allclose(pts[:, 0], np.linspace(10.0, 12.0, 11))
    assert np.allclose(pts[-1, 1:], [1.0, 3.0])


def test_intent_centres_drop_stale_intents_and_rims_ring_each_centre() -> None:
    fresh = intent_points((0.0, 0.0, 0.0), 0.5, 0.0, 10.0, 2.0)
    stale = intent_points((5.0, 5.0, 0.0), 0.5, 0.0, 8.0, 2.0)
    centres = intent_centres([fresh, stale], now=10.2, max_age_s=0.5)
    assert np.allclose(centres, fresh[:, 1:])  # all samples from 9.7 s on; none of the stale
    assert intent_centres([stale], now=10.2, max_age_s=0.5).shape == (0, 2)
    rim = rim_points(centres[:2], 0.17).reshape(2, -1, 2)
    assert np.allclose(np.hypot(*(rim - centres[:2, None, :]).transpose(2, 0, 1)), 0.17)


def test_path_intent_announces_the_path_ahead_even_when_stopped() -> None:
    pts = path_intent(np.array([0.0, 0.0]), np.array([[1.0, 0.0], [1.0, 1.0]]), 0.5, 3.0, 2.0)
    assert np.allclose(pts[:, 0], np.linspace(3.0, 5.0, 11))
    assert np.allclose(pts[5, 1:], [0.5, 0.0]) and np.allclose(pts[-1, 1:], [1.0, 0.0])
    end = path_intent(np.array([0.0, 0.0]), np.array([[0.3, 0.0]]), 0.5, 3.0, 2.0)
    assert np.allclose(end[-1, 1:], [0.3, 0.0])  # clipped at the path's end


def _idle_among(peer_path: np.ndarray, seconds: float, dt: float = 0.1):
    """An idle robot at the origin and a peer following ``peer_path`` at 0.25 m/s, stopping
    (as its DWA would) while its body would come within 5 cm of the idle one's. Returns the
    idle robot's final pose and the closest the two centres came."""
    idle, pose, velocity = FollowState(np.zeros((0, 2))), (0.0, 0.0, 0.0), (0.0, 0.0)
    peer, closest = peer_path[0].astype(float), math.inf
    for k in range(int(seconds / dt)):
        t = k * dt
        ahead = peer_path[1:][np.hypot(*(peer_path[1:] - peer).T) > 1e-9]
        centres = intent_centres([path_intent(peer, ahead, 0.25, t, 2.0)], t, 0.5)
        idle, result = keep_clear(
            idle, pose, velocity, np.zeros((0, 2)), centres, DWA, 0.17, dt, AGENT
        )
        velocity = (result.v, result.w)
        xs, ys, ths = rollout(pose, np.array([result.v]), np.array([result.w]), np.array([dt]))
        pose = (float(xs[0, 0]), float(ys[0, 0]), float(ths[0, 0]))
        if len(ahead):
            step = ahead[0] - peer
            nxt = peer + step * min(1.0, 0.025 / float(np.hypot(*step)))
            if math.dist(nxt, pose[:2]) >= 2 * 0.17 + 0.05:
                peer = nxt
        closest = min(closest, math.dist(peer, pose[:2]))
    return pose, peer, closest


def test_an_idle_robot_makes_way_for_a_peer_and_otherwise_stands_still() -> None:
    through = np.array([[-1.0, 0.0], [1.5, 0.0]])
    pose, peer, closest = _idle_among(through, 30.0)
    assert np.allclose(peer, through[-1])  # the peer got through
    assert closest >= 2 * 0.17  # and the bodies never touched
    assert abs(pose[1]) > 2 * 0.17 - 0.05  # the idle robot stepped off its line
    # a peer that passes at a distance leaves it where it is
    aside = np.array([[-1.0, 1.0], [1.5, 1.0]])
    assert _idle_among(aside, 15.0)[0] == (0.0, 0.0, 0.0)
