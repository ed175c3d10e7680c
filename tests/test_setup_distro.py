"""The shell side of the ROS 2 distros (scripts/distro.sh, sourced by setup.sh and env.sh): which
distro and underlay a machine gets, where its venv / tooling / colcon build live, the discovery
variables, the switch between distros in one shell; the vendored launch tooling sources."""
import hashlib
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TP = ROOT / 'third_party' / 'ros2'
WHEEL_DISTROS = ('jazzy', 'kilted')
SHOW = ('_kp_distro _kp_underlay _kp_venv _kp_reqs _kp_tools _kp_build _kp_install ROS_DISTRO '
        'ROS_AUTOMATIC_DISCOVERY_RANGE ROS_LOCALHOST_ONLY PATH PYTHONPATH AMENT_PREFIX_PATH').split()


def _distro(env_over, script='source scripts/distro.sh'):
    """Source ``script`` in a clean bash with ``env_over``; its variables (or its error)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ('ROS_DISTRO', 'ROS_DISTRO_PATH', 'ROS_LOCALHOST_ONLY')}
    env.update(env_over)
    show = '; '.join(f'echo "{v}=${{{v}-<unset>}}"' for v in SHOW)
    res = subprocess.run(['bash', '-c', f'{script} || exit 3; {show}'], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=60)
    out = dict(line.split('=', 1) for line in res.stdout.splitlines() if '=' in line)
    return res.returncode, out, res.stderr


def _system(distro):
    return f'/opt/ros/{distro}' if Path(f'/opt/ros/{distro}/setup.bash').is_file() else ''


@pytest.mark.parametrize('distro', WHEEL_DISTROS)
def test_each_wheel_distro_has_its_own_venv_tooling_and_build(distro):
    rc, v, err = _distro({'ROS_DISTRO': distro})
    assert rc == 0, err
    assert v['_kp_distro'] == v['ROS_DISTRO'] == distro
    assert v['_kp_venv'] == f'{ROOT}/.venv-{distro}'
    assert v['_kp_build'] == f'{ROOT}/build/{distro}' and v['_kp_install'] == f'{ROOT}/install/{distro}'
    assert v['_kp_underlay'] == _system(distro)
    if not _system(distro):   # the pinned wheels and the vendored tooling
        assert v['_kp_reqs'] == f'requirements-{distro}.txt requirements-py.txt'
        assert v['_kp_tools'] == f'{ROOT}/.venv-{distro}/ros2-tools'
        assert (ROOT / f'requirements-{distro}.txt').is_file()
        assert sorted(TP.glob(f'{distro}/*.tar.gz'))
    assert v['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert v['ROS_LOCALHOST_ONLY'] == '<unset>'   # deprecated since Jazzy: warns when set


def test_default_is_a_system_ros_else_jazzy():
    rc, v, err = _distro({})
    assert rc == 0, err
    systems = [d for d in ('jazzy', 'kilted', 'humble', 'rolling') if _system(d)]
    assert v['_kp_distro'] == (systems[0] if systems else 'jazzy')
    assert v['_kp_underlay'] == (_system(systems[0]) if systems else '')


def test_a_distro_without_wheels_or_system_install_is_refused_in_one_line():
    if _system('galactic'):
        pytest.skip('this machine has /opt/ros/galactic')
    rc, v, err = _distro({'ROS_DISTRO': 'galactic'})
    assert rc == 3 and len(err.strip().splitlines()) == 1, err
    assert 'galactic' in err and 'jazzy kilted' in err


def test_a_system_install_by_path_humble_gets_localhost_only(tmp_path):
    prefix = tmp_path / 'humble'
    prefix.mkdir()
    (prefix / 'setup.bash').write_text('')
    rc, v, err = _distro({'ROS_DISTRO_PATH': str(prefix), 'ROS_DISTRO': 'jazzy'})
    assert rc == 0, err
    assert v['_kp_distro'] == 'humble' and v['_kp_underlay'] == str(prefix)
    assert v['_kp_reqs'] == 'requirements-py.txt' and v['_kp_tools'] == ''   # no wheels, no tooling build
    assert v['ROS_LOCALHOST_ONLY'] == '1'     # Humble has no ROS_AUTOMATIC_DISCOVERY_RANGE
    rc, v, err = _distro({'ROS_DISTRO_PATH': str(tmp_path / 'nothing')})
    assert rc == 3 and 'no setup.bash' in err


def test_switching_distro_in_one_shell_drops_the_other_distros_paths():
    other = f'{ROOT}/.venv-kilted/bin:{ROOT}/install/kilted/viz/bin'
    rc, v, err = _distro({'ROS_DISTRO': 'jazzy', 'PATH': f'{other}:/usr/bin:/bin',
                          'PYTHONPATH': f'{ROOT}/.venv-kilted/ros2-tools/lib/python3.11/site-packages:/x',
                          'AMENT_PREFIX_PATH': f'{ROOT}/install/kilted/viz:{ROOT}/.venv-kilted'})
    assert rc == 0, err
    assert v['PATH'] == '/usr/bin:/bin'
    assert v['PYTHONPATH'] == '/x'
    assert v['AMENT_PREFIX_PATH'] == '<unset>'


def test_env_sh_in_this_suite_put_this_distro_on_the_paths():
    """The suite itself runs in the environment scripts/env.sh made (make test): the distro it
    says, with its own venv and overlay."""
    distro = os.environ.get('ROS_DISTRO')
    assert distro, 'ROS_DISTRO unset: run the suite through make test / source scripts/env.sh'
    import rclpy
    import skeleton_msgs
    assert os.environ.get('KINECT_POSTURE_ROS', '').startswith(('wheels:', 'system:'))
    if os.environ['KINECT_POSTURE_ROS'].startswith('wheels:'):
        assert Path(rclpy.__file__).is_relative_to(ROOT / f'.venv-{distro}'), rclpy.__file__
        assert Path(os.environ['KINECT_POSTURE_LAUNCH_TOOLING']) == ROOT / f'.venv-{distro}' / 'ros2-tools'
    assert (ROOT / 'install' / distro) in Path(skeleton_msgs.__file__).parents, skeleton_msgs.__file__


def test_vendored_tooling_sources_are_the_recorded_release_tarballs():
    lines = (TP / 'SHA256SUMS').read_text().split('\n')
    sums = dict(reversed(line.split()) for line in lines if line.strip())
    on_disk = {str(p.relative_to(TP)) for p in TP.glob('*/*.tar.gz')}
    assert set(sums) == on_disk
    assert {name.split('/')[0] for name in sums} == set(WHEEL_DISTROS)
    for name, digest in sums.items():
        assert hashlib.sha256((TP / name).read_bytes()).hexdigest() == digest, name
    if (ROOT / '.git').exists():   # *.tar.gz must not fall to a .gitignore pattern
        ignored = subprocess.run(['git', 'check-ignore', *sorted(on_disk)], cwd=TP,
                                 capture_output=True, text=True).stdout.split()
        assert not ignored, ignored


def test_tooling_build_script_refuses_an_unknown_distro_in_one_line(tmp_path):
    res = subprocess.run(['bash', str(TP / 'build-into-venv.sh'), 'nosuch', str(tmp_path / 'x')],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 1 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert 'nosuch' in res.stderr and 'jazzy' in res.stderr and 'kilted' in res.stderr


def test_vendored_hri_msgs_is_the_recorded_release_tarball(tmp_path):
    """REP-155's messages build from third_party/hri_msgs (no ../shared): the tarball is the one
    SHA256SUMS records, tracked, and unpack.sh gives colcon its package."""
    hri = ROOT / 'third_party' / 'hri_msgs'
    (line,) = [x for x in (hri / 'SHA256SUMS').read_text().splitlines() if x.strip()]
    digest, name = line.split()
    assert hashlib.sha256((hri / name).read_bytes()).hexdigest() == digest
    if (ROOT / '.git').exists():
        assert not subprocess.run(['git', 'check-ignore', name], cwd=hri, capture_output=True,
                                  text=True).stdout.split()
    out = subprocess.run(['bash', str(hri / 'unpack.sh'), str(tmp_path)], capture_output=True,
                         text=True, check=True).stdout.strip()
    assert (Path(out) / 'package.xml').read_text().count('<name>hri_msgs</name>') == 1
    assert (Path(out) / 'msg' / 'IdsList.msg').is_file()
