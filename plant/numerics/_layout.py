"""Named parts of a packed state vector, for numpy arrays and casadi symbols alike.

A recursive observer keeps everything it carries from one sample to the next
in one flat vector ``z`` (so that casadi can compile its step). A
:class:`StateLayout` names the parts of that vector once; the observer then
reads ``s = layout.unpack(z)``, ``s.x``, ``s.S``, ... and writes
``layout.pack(o, x=..., S=..., ...)``, never an offset by hand. It is the
same idea as python-control's labelled signals (``stochsys`` packs
``[xhat, P]``) and do-mpc's named states.
"""

from types import SimpleNamespace

import numpy as np

__all__ = ["StateLayout"]


class StateLayout:
    """Names, sizes and slices of a packed vector.

    Parameters
    ----------
    *parts : (str, int)
        ``(name, size)`` in packing order. A part of size 1 unpacks to a
        scalar (``z[k]``), any other to a slice (``z[a:b]``).

    Examples
    --------
    >>> layout = StateLayout(("x", 6), ("S", 9), ("t", 1))
    >>> layout.size
    16
    >>> z = layout.pack(None, x=np.zeros(6), S=np.eye(3).ravel(), t=0.5)
    >>> float(layout.unpack(z).t)
    0.5
    """

    def __init__(self, *parts):
        self.names = tuple(name for name, _ in parts)
        if len(set(self.names)) != len(self.names):
            raise ValueError(f"state part names must be unique; got {self.names}")
        self.sizes = {name: int(size) for name, size in parts}
        self.slices, k = {}, 0
        for name, size in parts:
            if int(size) < 1:
                raise ValueError(f"state part {name!r} must have a positive size; got {size}")
            self.slices[name] = slice(k, k + int(size))
            k += int(size)
        #: Length of the packed vector.
        self.size = k

    def __repr__(self):
        return "StateLayout(" + ", ".join(f"{n}={self.sizes[n]}" for n in self.names) + ")"

    def unpack(self, z, scalars=True):
        """The parts of ``z`` by name (a namespace: ``s.x``, ``s.S``).

        Parameters
        ----------
        z : ndarray or casadi.SX, shape (size,)
        scalars : bool
            Size-1 parts as scalars (default); False: every part a vector,
            for code written for any size (a model with one channel).

        Returns
        -------
        types.SimpleNamespace
            Views into ``z``.
        """
        return SimpleNamespace(**{name: (z[self.slices[name].start] if scalars and self.sizes[name] == 1 else
                                         z[self.slices[name]]) for name in self.names})

    def pack(self, o, **parts):
        """One flat vector from every part, by name.

        Parameters
        ----------
        o : ops namespace (:func:`fmscal.plant.numerics.ops`) or None
            None packs numbers with numpy.
        **parts
            Exactly the layout's names; each a scalar or a vector of its size.

        Returns
        -------
        ndarray or casadi.SX, shape (size,)
        """
        missing = [n for n in self.names if n not in parts]
        extra = [n for n in parts if n not in self.sizes]
        if missing or extra:
            raise ValueError(f"pack needs exactly {', '.join(self.names)}; missing {missing}, unknown {extra}")
        items = [parts[n] for n in self.names]
        if o is None:
            z = np.concatenate([np.ravel(np.asarray(v, dtype=float)) for v in items])
            if len(z) != self.size:
                raise ValueError(f"packed state has {len(z)} entries; expected {self.size} ({self!r})")
            return z
        return o.vcat(items)

    def part(self, Z, name):
        """A named part of every row of a history ``Z``, shape (N, size of the part)."""
        return Z[:, self.slices[name]]

