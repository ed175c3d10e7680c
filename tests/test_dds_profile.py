"""The Fast DDS profile of the graph's start (kinect_bringup.dds_profile, config/fastdds_startup.xml):
set for Fast DDS only and only when the user has no profile of their own (theirs wins), and a
profile the installed Fast DDS loads without an error (a malformed copy shows that the check sees
one)."""
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

import domains  # noqa: E402  (tests/domains.py)
from kinect_bringup import dds_profile
from kinect_bringup.dds_profile import PROFILE_VARS, profile_var, startup_profile_env

NS = '{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}'


def test_set_for_fast_dds_when_the_user_has_no_profile(tmp_path):
    for rmw in ({}, {'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp'},
                {'RMW_IMPLEMENTATION': 'rmw_fastrtps_dynamic_cpp'}):
        for distro, var in (('jazzy', 'FASTRTPS_DEFAULT_PROFILES_FILE'),
                            ('kilted', 'FASTDDS_DEFAULT_PROFILES_FILE')):
            # one name only: Kilted's middleware loads a FASTRTPS_ file too (and warns), and a
            # profile loaded twice is an error
            env = startup_profile_env(dict(rmw, ROS_DISTRO=distro), cwd=tmp_path)
            assert list(env) == [var], (rmw, distro)
            assert env[var].endswith(dds_profile.PROFILE_FILE) and os.path.isfile(env[var])


def test_the_users_own_profile_wins(tmp_path):
    for var in PROFILE_VARS:   # either distro's variable
        assert startup_profile_env({var: '/home/me/my_profile.xml'}, cwd=tmp_path) == {}
    for name in dds_profile.CWD_PROFILES:   # or the default file Fast DDS loads from the cwd
        d = tmp_path / name.split('.')[0]
        d.mkdir()
        (d / name).write_text('<profiles/>')
        assert startup_profile_env({}, cwd=d) == {}
    # another middleware: nothing set
    assert startup_profile_env({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}, cwd=tmp_path) == {}


def test_use_startup_profile_adds_to_the_environment(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    env = {'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp'}
    added = dds_profile.use_startup_profile(env)
    assert added and all(env[k] == v for k, v in added.items())
    assert dds_profile.use_startup_profile(env) == {}   # now set: left as it is


def test_the_launch_action_sets_it_in_the_launch_environment(tmp_path, monkeypatch):
    pytest.importorskip('launch')
    from launch.actions import SetEnvironmentVariable
    from kinect_bringup.launch_nodes import startup_profile
    monkeypatch.chdir(tmp_path)

    class Context:
        environment = {}

    actions = startup_profile().execute(Context())
    assert actions and all(isinstance(a, SetEnvironmentVariable) for a in actions)
    Context.environment = {PROFILE_VARS[1]: '/home/me/mine.xml'}
    assert not startup_profile().execute(Context())


def test_the_profile_changes_the_initial_announcements_only():
    root = ET.parse(dds_profile.profile_path()).getroot()
    participants = root.findall(f'{NS}participant')
    assert len(participants) == 1 and participants[0].get('is_default_profile') == 'true'
    # only <rtps><builtin><discovery_config><initialAnnouncements>: where the announcements go
    # stays what the ROS middleware sets
    leaves = [e.tag.replace(NS, '') for e in participants[0].iter() if len(e) == 0]
    assert leaves == ['count', 'sec', 'nanosec']
    ia = participants[0].find(f'{NS}rtps/{NS}builtin/{NS}discovery_config/{NS}initialAnnouncements')
    count = int(ia.find(f'{NS}count').text)
    period = int(ia.find(f'{NS}period/{NS}sec').text) + int(ia.find(f'{NS}period/{NS}nanosec').text) * 1e-9
    assert count * period > 0.5   # longer than Fast DDS's default (5 x 0.1 s)


# (the middleware makes the participant, and loads the profile, with the first node)
_PARTICIPANT = ('import rclpy; c = rclpy.Context(); rclpy.init(context=c); '
                'rclpy.create_node("profile_check", context=c).destroy_node(); '
                'rclpy.try_shutdown(context=c)')


def _xml_errors(profile) -> str:
    pytest.importorskip('rclpy')
    with domains.claimed(int(os.environ.get('ROS_DOMAIN_ID', '0')) + 23) as domain:
        env = domains.env_with(domain)
        env[profile_var(env)] = str(profile)   # as the launch sets it
        p = subprocess.run([sys.executable, '-c', _PARTICIPANT], env=env, capture_output=True,
                           text=True, timeout=60)
    assert p.returncode == 0, p.stderr[-2000:]
    return '\n'.join(line for line in (p.stdout + p.stderr).splitlines()
                     if 'XMLPARSER' in line or 'PROFILES_FILE' in line)


@pytest.mark.ros
def test_fast_dds_loads_the_profile_without_an_error(tmp_path):
    assert _xml_errors(dds_profile.profile_path()) == ''
    bad = tmp_path / 'bad.xml'
    bad.write_text(dds_profile.profile_path().read_text().replace('<count>', '<counts>')
                   .replace('</count>', '</counts>'))
    assert _xml_errors(bad) != ''


@pytest.mark.ros
def test_the_matching_experiment_reports_every_case(monkeypatch, capsys):
    """kinect_experiments.discovery_match (docs/startup.md's measure of the matching wait): a
    publisher and a subscriber process per run, with and without the profile, each matched."""
    from kinect_experiments import discovery_match
    with domains.claimed(int(os.environ.get('ROS_DOMAIN_ID', '0')) + 29) as domain:
        monkeypatch.setenv('ROS_DOMAIN_ID', str(domain))
        assert discovery_match.main(['--runs', '1', '--gap', '0.3']) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if ' first: ' in line]
    assert len(rows) == 4 and not any('never' in r for r in rows), rows
