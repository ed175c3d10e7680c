"""startup_cpu reads /proc: a command name with spaces and parentheses does not shift the fields,
and the processes are named as the launch names them."""
from kinect_experiments.startup_cpu import cpu_seconds, process_name, stat_fields


def test_stat_fields_after_a_command_name_with_spaces_and_parentheses():
    line = ('4242 (python3 (x) y) S 1 4242 4242 0 -1 4194560 100 0 0 0 '
            '250 50 0 0 20 0 3 0 12345 1000 10 18446744073709551615\n')
    f = stat_fields(line)
    assert f[0] == 'S' and f[3] == '4242'          # state, session
    assert cpu_seconds(f, 100.0) == 3.0            # (250 + 50) ticks at 100 Hz


def test_process_names():
    assert process_name(['/venv/bin/python3', '/venv/ros2-tools/bin/ros2', 'launch',
                         'kinect_bringup', 'demo.launch.py']) == 'launch'
    assert process_name(['/venv/bin/python', '/ws/install/jazzy/pose_reconstruction/lib/'
                         'pose_reconstruction/reconstruction', '--managed']) == 'reconstruction'
    assert process_name([]) == '?'


def test_the_cpu_of_children_that_ended_is_counted():
    # utime stime cutime cstime: a library that probed something in a subprocess at import
    line = ('4242 (physics) S 1 4242 4242 0 -1 4194560 100 0 0 0 '
            '250 50 30 20 20 0 3 0 12345 1000 10 18446744073709551615\n')
    assert cpu_seconds(stat_fields(line), 100.0) == 3.5
