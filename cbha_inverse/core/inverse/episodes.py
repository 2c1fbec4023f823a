"""
Episodes of a controller's abnormal tick statuses, so that each is reported once, not per tick.

A tick whose state is off equilibrium (``'not_converged'``) or whose target lies outside the
actuators' reach (``'unreachable'``) is a condition the user must hear of, but at 100 Hz one
line per tick would bury everything else. :class:`StatusEpisodes` turns the ticks' statuses
into episodes: one starts at the first tick of a condition, ends after ``clear_ticks``
consecutive ticks without it (so a status flickering at a threshold stays one episode), and
keeps its duration and its worst figure (the distance in metres the condition is measured by).
A node logs the start and the end of each episode and reports the ongoing one in its
diagnostics.
"""

from dataclasses import dataclass
import math

CONDITIONS = ('not_converged', 'unreachable')
"""The tick statuses that start an episode, most severe first."""


@dataclass
class Episode:
    """
    One ongoing or ended episode.

    Attributes
    ----------
    condition : str
        One of :data:`CONDITIONS`.
    started : float  [s]
        Clock time of its first tick.
    last : float  [s]
        Clock time of its last tick with the condition.
    ticks : int
        Ticks with the condition.
    figure : float  [m]
        The condition's distance at its last tick.
    worst : float  [m]
        The largest distance over the episode.

    """

    condition: str
    started: float
    last: float
    ticks: int
    figure: float
    worst: float

    @property
    def duration(self):
        """Return the time from its first to its last tick with the condition [s]."""
        return self.last - self.started


class StatusEpisodes:
    """
    Track the episodes of abnormal statuses over a sequence of ticks.

    Parameters
    ----------
    clear_ticks : int
        Consecutive ticks without the condition that end an episode (>= 1).

    Attributes
    ----------
    current : Episode or None
        The ongoing episode.

    """

    def __init__(self, clear_ticks=10):
        """Start with no episode."""
        if int(clear_ticks) < 1:
            raise ValueError(f'clear_ticks must be >= 1, got {clear_ticks!r}')
        self.clear_ticks = int(clear_ticks)
        self.current = None
        self._clear = 0

    def update(self, status, figure, now):
        """
        Account one tick.

        Parameters
        ----------
        status : str
            The tick's status (any; only :data:`CONDITIONS` start or extend an episode).
        figure : float  [m]
            The condition's distance at this tick (ignored for other statuses).
        now : float  [s]
            Clock time of the tick.

        Returns
        -------
        started : Episode or None
            The episode this tick started (a new condition, or another than the ongoing one).
        ended : Episode or None
            The episode this tick ended (``clear_ticks`` ticks without its condition, or
            replaced by another condition).

        """
        started = ended = None
        if status in CONDITIONS:
            self._clear = 0
            figure = float(figure)
            episode = self.current
            if episode is not None and episode.condition != status:
                ended, episode = episode, None
            if episode is None:
                episode = self.current = started = Episode(status, now, now, 0, figure, figure)
            episode.last, episode.ticks, episode.figure = now, episode.ticks + 1, figure
            if not math.isnan(figure):
                worst = episode.worst
                episode.worst = figure if math.isnan(worst) else max(worst, figure)
        elif self.current is not None:
            self._clear += 1
            if self._clear >= self.clear_ticks:
                ended, self.current, self._clear = self.current, None, 0
        return started, ended

    def reset(self):
        """Forget the ongoing episode (a reset of the controller)."""
        self.current = None
        self._clear = 0
