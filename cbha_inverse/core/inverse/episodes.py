"""
Episodes of a controller's abnormal tick statuses, so that each is reported once, not per tick.

A tick whose state is off equilibrium (``'not_converged'``), whose obstacle rows cannot all hold
(``'obstacle'``, ``docs/obstacles.md``) or whose target lies outside the actuators' reach
(``'unreachable'``) is a condition the user must hear of, but at 100 Hz one
line per tick would bury everything else. :class:`StatusEpisodes` turns the ticks' statuses
into episodes: one starts at the first tick of any condition and ends after ``clear_ticks``
consecutive ticks with none, so a status flickering at a threshold, or between two
conditions (a target at the edge of the reach), stays one episode. An episode keeps, per
condition, its ticks, last and worst figure (the distance in metres the condition is measured
by), and names the condition most of its ticks had. A node logs the start and the end of each
episode and reports the ongoing one in its diagnostics.
"""

from dataclasses import dataclass, field
import math

CONDITIONS = ('not_converged', 'obstacle', 'unreachable')
"""The tick statuses that start or extend an episode."""


@dataclass
class Episode:
    """
    One ongoing or ended episode.

    Attributes
    ----------
    started : float  [s]
        Clock time of its first tick.
    last : float  [s]
        Clock time of its last tick with a condition.
    ticks : dict of str to int
        Ticks of each condition.
    figures : dict of str to float  [m]
        Each condition's distance at its last tick.
    worst : dict of str to float  [m]
        Each condition's largest distance over the episode.

    """

    started: float
    last: float
    ticks: dict = field(default_factory=dict)
    figures: dict = field(default_factory=dict)
    worst: dict = field(default_factory=dict)

    @property
    def condition(self):
        """Return the condition most of its ticks had (the more severe one on a tie)."""
        return max(CONDITIONS, key=lambda c: (self.ticks.get(c, 0), c == CONDITIONS[0]))

    @property
    def figure(self):
        """Return the distance of :attr:`condition` at its last tick [m]."""
        return self.figures[self.condition]

    @property
    def duration(self):
        """Return the time from its first to its last tick with a condition [s]."""
        return self.last - self.started

    def add(self, condition, figure, now):
        """Account one tick of ``condition`` with distance ``figure`` [m] at time ``now`` [s]."""
        self.last = now
        self.ticks[condition] = self.ticks.get(condition, 0) + 1
        self.figures[condition] = figure
        worst = self.worst.get(condition, math.nan)
        if not math.isnan(figure):
            self.worst[condition] = figure if math.isnan(worst) else max(worst, figure)
        else:
            self.worst.setdefault(condition, math.nan)


class StatusEpisodes:
    """
    Track the episodes of abnormal statuses over a sequence of ticks.

    Parameters
    ----------
    clear_ticks : int
        Consecutive ticks without a condition that end an episode (>= 1).

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
            The episode this tick started.
        ended : Episode or None
            The episode this tick ended (``clear_ticks`` ticks without a condition).

        """
        started = ended = None
        if status in CONDITIONS:
            self._clear = 0
            if self.current is None:
                self.current = started = Episode(now, now)
            self.current.add(status, float(figure), now)
        elif self.current is not None:
            self._clear += 1
            if self._clear >= self.clear_ticks:
                ended, self.current, self._clear = self.current, None, 0
        return started, ended

    def reset(self):
        """Forget the ongoing episode (a reset of the controller)."""
        self.current = None
        self._clear = 0
