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
