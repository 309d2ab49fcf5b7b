"""Attack: return an np.ndarray subclass that lies to the action check and raises when used.

act() returns an instance of a subclass of np.ndarray holding 5.0 in every entry (outside
[-1, 1]) whose __array_ufunc__ lies (np.isfinite says all finite, np.abs says all zero, so an
in-process range check passes), and whose astype, __array__, __float__, __bool__, __len__,
__getitem__, __iter__, __repr__, __str__, __format__, __reduce__ and tolist raise. In-process the
check either lets 5.0 through or the evaluator dies with a traceback from inside the subclass.

An honest evaluator must treat the action as plain data (bytes the controller's process sends):
either it receives the 18 floats (all 5.0, outside [-1, 1]) and stops the run with one "error: ..."
line naming this file, or it rejects the object with one such line; never a traceback.
"""

import numpy as np


class Hostile(Exception):
    pass


def _raise(*args, **kwargs):
    raise Hostile("hexbench-attack: the action object refuses")


class EvilArray(np.ndarray):
    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        if ufunc is np.isfinite:
            return np.ones(self.size, dtype=bool).reshape(self.shape)
        if ufunc is np.absolute:
            return np.zeros(self.size).reshape(self.shape)
        plain = [np.asarray(x) if isinstance(x, EvilArray) else x for x in inputs]
        return getattr(ufunc, method)(*plain, **kwargs)

    astype = _raise
    __array__ = _raise
    __float__ = _raise
    __bool__ = _raise
    __len__ = _raise
    __getitem__ = _raise
    __iter__ = _raise
    __repr__ = _raise
    __str__ = _raise
    __format__ = _raise
    __reduce__ = _raise
    __reduce_ex__ = _raise
    tolist = _raise


class Subclass:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step >= 3:
            return np.full(18, 5.0, dtype=np.float32).view(EvilArray)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Subclass()
