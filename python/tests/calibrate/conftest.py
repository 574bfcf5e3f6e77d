"""The shared 60 s room of four references (calibration_rooms.py builds rooms)."""

import pytest

from calibration_rooms import NEAR, room


@pytest.fixture(scope="module")
def near_room():
    return room(60.0, NEAR, seed=5)
