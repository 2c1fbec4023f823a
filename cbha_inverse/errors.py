"""
Errors that every layer of the package raises for bad configuration files.

A :class:`ConfigError` carries the file, the key (or line) and what is wrong; its message is one
line, ``<file>: <key>: <problem>``, which commands and nodes print as it is (exit code 2) instead
of a traceback.
"""


class ConfigError(ValueError):
    """
    A configuration file (scene, segment, geometry, params, camera) is wrong.

    Parameters
    ----------
    path : str or os.PathLike
        The file that is wrong.
    key : str
        Where in the file: a dotted key (``chain.sections[1].segment``) or ``line N``.
    problem : str
        What is wrong, in words a user can act on.

    """

    def __init__(self, path, key, problem):
        self.path = str(path)
        self.key = str(key)
        self.problem = str(problem)
        super().__init__(f'{self.path}: {self.key}: {self.problem}')


#: Exit status of a command or node stopped by a bad configuration file or parameter.
CONFIG_ERROR_EXIT = 2


def report_error(program, error, status, stream=None):
    """
    Print the error that stops a command or node as one line on stderr and return its status.

    The one place where commands and nodes turn an exception into what the user sees:
    ``<program>: error: <message>``, no traceback.

    Parameters
    ----------
    program : str
        The command or node name.
    error : Exception or str
        The error; its message is printed on one line (newlines become ``; ``).
    status : int
        The exit status to return.
    stream : file-like, optional
        Where to print (default ``sys.stderr``).

    Returns
    -------
    int
        ``status``.

    """
    import sys
    text = '; '.join(line.strip() for line in str(error).splitlines() if line.strip())
    print(f'{program}: error: {text}', file=sys.stderr if stream is None else stream, flush=True)
    return status


def report_config_error(program, error, stream=None):
    """
    Print a configuration error as one line on stderr and return :data:`CONFIG_ERROR_EXIT`.

    A :class:`ConfigError` (or a parameter or input error) prints
    ``<program>: error: <file>: <key>: <problem>`` (:func:`report_error`).

    Parameters
    ----------
    program : str
        The command or node name.
    error : Exception or str
        The error.
    stream : file-like, optional
        Where to print (default ``sys.stderr``).

    Returns
    -------
    int
        :data:`CONFIG_ERROR_EXIT` (2).

    """
    return report_error(program, error, CONFIG_ERROR_EXIT, stream)
