"""Issue 26 item 4: the cell file names its controller backend, found through one table; each
backend declares what it offers beyond the LLI; the kinematic one follows its setpoints exactly."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.robot.backends import BACKENDS, backend
from landscape.robot.cell import CellError, load_cell, parse_cell
from landscape.robot.controller import Capability, EnableState, JointCmd, Status

from support import cell_file


def test_the_cell_file_names_its_backend_and_an_unknown_one_is_refused_naming_the_key(tmp_path):
    assert load_cell().controller.backend == "pybullet"
    kinematic = cell_file(tmp_path, {'backend = "pybullet"': 'backend = "kinematic"'})
    assert load_cell(kinematic).controller.backend == "kinematic"
    text = open(kinematic).read().replace('backend = "kinematic"', 'backend = "cs9"')
    with pytest.raises(CellError) as refused:
        parse_cell(text, "cell.toml")
    assert "cell.toml" in str(refused.value) and "backend" in str(refused.value)
    with pytest.raises(ValueError, match="kinematic"):
        backend("cs9")


@pytest.mark.parametrize("name", sorted(BACKENDS))
def test_each_backend_offers_what_it_declares(name):
    controller = backend(name)(load_cell())
    try:
        offered = controller.capabilities()
        assert Capability.PANEL in offered
        assert controller.operate_panel("open_door") == (False, True)
        if Capability.WORLD in offered:
            assert "block_1" in controller.part_states()
        else:
            with pytest.raises(NotImplementedError):
                controller.part_states()
    finally:
        controller.destroy()


def test_the_kinematic_backend_follows_its_setpoints_exactly_and_checks_them():
    cell = load_cell()
    controller = backend("kinematic")(cell)
    try:
        assert controller.init() is Status.OK and controller.enable() is Status.OK
        while controller.state().enable is not EnableState.ENABLED:
            controller.step()
        q = controller.get().pos
        step = np.full(6, 1e-3)
        assert controller.set(JointCmd(q + step, step / cell.controller.cycle_time)) is Status.OK
        controller.step()
        assert np.array_equal(controller.get().pos, q + step)
        # A command no drive could follow is refused and the drives go off, as on pybullet.
        assert controller.set(JointCmd(q + 1.0, np.zeros(6))) is Status.ERROR
        assert controller.state().enable is EnableState.DISABLED
        assert not np.any(controller.read_sensor("force_sensor"))
    finally:
        controller.destroy()
