"""User errors cross process boundaries intact: the non-linear paths run in a process pool."""

from __future__ import annotations

import pickle
from concurrent.futures import ProcessPoolExecutor

import pytest

from engine import errors
from engine.errors import GridshellError, MechanismError


def _raise_mechanism() -> None:
    raise MechanismError("the frame is a mechanism", n_modes=2, hint="support more nodes")


@pytest.mark.parametrize("error", [errors.InputError("bad value", hint="fix it"), errors.MeshError("not manifold"),
                                   errors.SelectionError("no node"), errors.ConvergenceError("no path", hint="h"),
                                   MechanismError("a mechanism", n_modes=3, hint="support more nodes")])
def test_user_errors_pickle_with_their_class_message_and_hint(error):
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is type(error)
    assert str(back) == str(error) and back.hint == error.hint
    assert getattr(back, "n_modes", None) == getattr(error, "n_modes", None)


def test_a_mechanism_raised_in_a_worker_process_arrives_as_a_mechanism():
    """Before, unpickling MechanismError (a required keyword argument) broke the whole pool."""
    with ProcessPoolExecutor(max_workers=1) as pool:
        with pytest.raises(MechanismError, match="mechanism") as caught:
            pool.submit(_raise_mechanism).result(timeout=60)
    assert isinstance(caught.value, GridshellError) and caught.value.n_modes == 2
