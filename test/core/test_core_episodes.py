"""Episodes of abnormal tick statuses: one start and one end per episode, whatever the ticks."""

import math

from cbha_inverse.core.inverse.episodes import StatusEpisodes
import pytest


def run(episodes, ticks):
    """Feed ``(status, figure)`` ticks at 10 ms; return the (time, started, ended) events."""
    events = []
    for i, (status, figure) in enumerate(ticks):
        started, ended = episodes.update(status, figure, 0.01 * i)
        if started or ended:
            events.append((round(0.01 * i, 2), started, ended))
    return events


def test_a_flickering_condition_is_one_episode_with_its_worst_figure():
    """A status that leaves for fewer than ``clear_ticks`` ticks does not end the episode."""
    episodes = StatusEpisodes(clear_ticks=3)
    ticks = ([('solved', 0.0)] * 2 + [('unreachable', 0.004), ('saturated', 0.0009)] * 5
             + [('unreachable', 0.006), ('unreachable', 0.005)] + [('saturated', 0.0)] * 3)
    events = run(episodes, ticks)
    assert len(events) == 2
    (t0, started, none), (t1, none_too, ended) = events
    assert none is None and none_too is None and started is ended
    assert (t0, t1) == (0.02, 0.16)
    assert ended.condition == 'unreachable' and ended.ticks == {'unreachable': 7}
    assert ended.worst == {'unreachable': 0.006} and ended.figure == 0.005
    assert ended.duration == pytest.approx(0.13 - 0.02)
    assert episodes.current is None


def test_both_conditions_in_turn_are_one_episode_named_by_most_of_its_ticks():
    """A target at the edge of the reach: unreachable, now and then off equilibrium."""
    episodes = StatusEpisodes()
    ticks = [('not_converged', 0.03)] + [('unreachable', 0.2), ('unreachable', 0.19),
                                         ('not_converged', math.nan)] * 4
    events = run(episodes, ticks)
    assert len(events) == 1 and events[0][1] is episodes.current
    episode = episodes.current
    assert episode.ticks == {'not_converged': 5, 'unreachable': 8}
    assert episode.condition == 'unreachable' and episode.figure == 0.19
    assert episode.worst == {'not_converged': 0.03, 'unreachable': 0.2}
    # a tie names the more severe condition
    episode.ticks['not_converged'] = 8
    assert episode.condition == 'not_converged' and math.isnan(episode.figure)
    episodes.reset()
    assert episodes.current is None
    assert episodes.update('solved', 0.0, 1.0) == (None, None)


def test_normal_ticks_start_nothing_and_clear_ticks_is_checked():
    """``solved``, ``saturated`` and held statuses never start an episode; 0 clear ticks: error."""
    episodes = StatusEpisodes(clear_ticks=1)
    assert run(episodes, [(s, 1.0) for s in ('solved', 'saturated', 'rejected',
                                             'not_positive_definite', 'qp_fallback')]) == []
    with pytest.raises(ValueError, match='clear_ticks'):
        StatusEpisodes(clear_ticks=0)
