"""Option types known by a short name: the registries of reach algorithms and reduction methods.

A user may write ``"lin"`` or ``"girard"`` where an instance of an option type
(``ConservativeLinearization()``, ``Girard()``) is asked for;
:class:`NamedTypes` maps the names to the types and resolves either form.
"""

from __future__ import annotations

from reachconf.errors import OptionsError

__all__ = ["NamedTypes"]


class NamedTypes(dict):
    """A registry ``name -> type`` of the subclasses of ``base`` that have a ``name``.

    Parameters
    ----------
    base : type
        The base class of the option types.
    what : str
        What they are, for messages (``"reach algorithm"``).
    """

    def __init__(self, base: type, what: str):
        super().__init__()
        self.base, self.what = base, what

    def register(self, cls: type) -> type:
        """Make a subclass of ``base`` known by its ``name`` (usable as a class decorator)."""
        if not (isinstance(cls, type) and issubclass(cls, self.base) and getattr(cls, "name", "")):
            raise OptionsError(f"a {self.what} type must subclass {self.base.__name__} and have a name, got {cls!r}")
        self[cls.name] = cls
        return cls

    def resolve(self, value):
        """The instance for a name (a default-constructed one) or the instance itself.

        Raises
        ------
        OptionsError
            For an unknown name or an object of another type.
        """
        if isinstance(value, self.base):
            return value
        if isinstance(value, str) and value in self:
            return self[value]()
        raise OptionsError(f"unknown {self.what} {value!r}; use one of {tuple(self)} or an instance of "
                           f"{', '.join(c.__name__ for c in self.values())}")  # fmt: skip
