"""
The progress of a long fit as one line that updates in place (``cbha_identify``).

:class:`ProgressLine` takes the fit's progress messages: on a terminal it rewrites one line
(carriage return); into a file or a pipe, where a carriage return does not rewrite, it writes a
line at most every ``period`` seconds; ``verbose`` writes every message, ``quiet`` none. The last
message is always written when the line is closed.
"""

import sys
import time


class ProgressLine:
    """
    Show progress messages as one updating line.

    Parameters
    ----------
    stream : file-like, optional
        Where to write (default ``sys.stdout``).
    mode : str
        ``'line'`` (default), ``'verbose'`` (every message on its own line) or ``'quiet'``.
    period : float  [s]
        Off a terminal: least time between two written lines.
    clock : callable, optional
        Steady time [s] (default ``time.monotonic``).

    """

    def __init__(self, stream=None, mode='line', period=5.0, clock=time.monotonic):
        """Start with nothing shown."""
        if mode not in ('line', 'verbose', 'quiet'):
            raise ValueError(f"mode must be 'line', 'verbose' or 'quiet', got {mode!r}")
        self.stream = sys.stdout if stream is None else stream
        self.mode = mode
        self.period = float(period)
        self.clock = clock
        isatty = getattr(self.stream, 'isatty', None)
        self.terminal = bool(isatty and isatty())
        self.pending = None
        self.written_at = None
        self.width = 0

    def __call__(self, message):
        """Take one progress message."""
        message = str(message).strip()
        if self.mode == 'quiet':
            return
        if self.mode == 'verbose':
            self._write(message + '\n')
        elif self.terminal:
            self._write('\r' + message.ljust(self.width))
            self.width = len(message)
            self.pending = ''
        else:
            now = self.clock()
            if self.written_at is None or now - self.written_at >= self.period:
                self.written_at = now
                self._write(message + '\n')
                self.pending = None
            else:
                self.pending = message

    def close(self):
        """End the line: on a terminal a newline, elsewhere the last message if not written."""
        if self.pending is not None:
            self._write(self.pending + '\n')
        self.pending = None
        self.width = 0

    def _write(self, text):
        self.stream.write(text)
        self.stream.flush()
