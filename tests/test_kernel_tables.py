"""The kernel's tables and cache key stay complete as the kernel grows (no compiling here)."""

import re
from pathlib import Path

from numba.core.dispatcher import Dispatcher

from rodphase.result import HISTORY, HISTORY_COLUMNS, HISTORY_UNITS
from rodphase.rod import _jit, contact, kernel, neo_hookean, rotation


def test_history_slots_come_from_the_one_table_of_columns():
    slots = {name: getattr(kernel, name) for name in dir(kernel) if name.startswith("H_")}
    assert sorted(slots.values()) == list(range(kernel.N_HISTORY))
    assert kernel.N_HISTORY == len(HISTORY_COLUMNS) == len(HISTORY)
    assert set(HISTORY_COLUMNS) <= set(HISTORY_UNITS)  # and the derived columns' units
    assert HISTORY_COLUMNS[kernel.H_TIME] == "time"
    assert HISTORY_COLUMNS[kernel.H_START_ROTATION] == "start_rotation"


def test_control_table_and_diagnostic_slots_come_from_their_tables():
    """Each T_*/D_* index is a row of CONTROL_TABLES/DIAGNOSTICS, each row has one index,
    and every control table is a field of Controls (what Controls.tables() reads by name)."""
    import dataclasses

    from rodphase.rod import Controls

    for prefix, names, count in (("T_", kernel.CONTROL_TABLE_NAMES, kernel.N_TABLES),
                                 ("D_", kernel.DIAGNOSTIC_NAMES, kernel.N_INFO)):
        slots = {name: getattr(kernel, name) for name in dir(kernel) if name.startswith(prefix)}
        assert sorted(slots.values()) == list(range(count)) == list(range(len(names)))
        for name, index in slots.items():
            assert names[index] == name[len(prefix):].lower(), name
    fields = {f.name for f in dataclasses.fields(Controls)}
    assert set(kernel.CONTROL_TABLE_NAMES) <= fields
    tables = Controls(end_force=((0.0,), (3.0,))).tables()
    assert tables[kernel.T_END_FORCE] == ((0.0,), (3.0,)) and len(tables) == kernel.N_TABLES


def test_every_guard_the_kernel_can_trip_has_a_message_and_advice():
    codes = {getattr(kernel, name) for name in dir(kernel) if name.startswith("S_")}
    guards = codes - {kernel.S_COMPLETED, kernel.S_EQUILIBRIUM, kernel.S_WAKE}
    assert set(kernel.GUARDS) == guards
    for guard in kernel.GUARDS.values():
        assert guard.name and guard.message and guard.where and guard.advice.endswith(".")


def test_the_cache_key_covers_every_module_with_compiled_code():
    rod = Path(kernel.__file__).parent
    compiled = {f"rod/{p.name}" for p in rod.glob("*.py")
                if re.search(r"^from \._jit import njit", p.read_text(), re.M)}
    assert compiled <= set(_jit.KERNEL_MODULES)
    assert "result.py" in _jit.KERNEL_MODULES  # the history slots come from it


def test_every_cached_kernel_function_uses_the_source_keyed_cache():
    for module in (kernel, contact, neo_hookean, rotation):
        for name in dir(module):
            f = getattr(module, name)
            if isinstance(f, Dispatcher) and f.py_func.__module__ == module.__name__:
                assert isinstance(f._cache, _jit._KernelCache), name
