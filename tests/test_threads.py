"""`hrgjax._threads`: the flag that keeps XLA:CPU's Eigen pool from wedging on two cores."""

import os

from hrgjax._threads import FLAG, single_threaded_eigen


def test_the_flag_is_added_once_and_a_choice_already_made_is_kept():
    env = {}
    assert single_threaded_eigen(env) and env["XLA_FLAGS"] == FLAG
    assert not single_threaded_eigen(env) and env["XLA_FLAGS"] == FLAG
    env = {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    assert single_threaded_eigen(env)
    assert env["XLA_FLAGS"] == f"--xla_force_host_platform_device_count=2 {FLAG}"
    mine = "--xla_cpu_multi_thread_eigen=true"
    env = {"XLA_FLAGS": mine}
    assert not single_threaded_eigen(env) and env["XLA_FLAGS"] == mine
    # the suite itself (tests/conftest.py) runs with it, and so do the processes it starts
    assert "xla_cpu_multi_thread_eigen" in os.environ["XLA_FLAGS"]
