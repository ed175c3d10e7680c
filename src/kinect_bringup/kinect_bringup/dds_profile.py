"""The Fast DDS participant profile of the graph's start (``config/fastdds_startup.xml``): its
participants announce themselves for 5 s after they come up instead of 0.5 s, so that one started
a second or two after another meets it at once rather than at that one's next announcement (every
3 s). See docs/startup.md. No rclpy, no launch at import time.

Set only for Fast DDS (``RMW_IMPLEMENTATION`` unset or ``rmw_fastrtps*``), and only when the user
has no profile of their own: neither variable below set, no default profile file in the working
directory. The launch files set it for their processes (:func:`kinect_bringup.launch_nodes.
startup_profile`), ``demo`` for itself and its launch.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Dict, Mapping, Optional

PROFILE_FILE = 'fastdds_startup.xml'
# the default-profile variables of Fast DDS 2.x (Jazzy) and 3.x (Kilted), and the files each
# loads from the working directory
PROFILE_VARS = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
CWD_PROFILES = ('DEFAULT_FASTRTPS_PROFILES.xml', 'DEFAULT_FASTDDS_PROFILES.xml')
# the distros on Fast DDS 2.x, which reads only the first name; the later ones' (3.x) middleware
# also reads the first, with a deprecation warning, and loads the file twice when both are set
FAST_DDS_2 = ('humble', 'iron', 'jazzy')


def profile_var(environ: Mapping[str, str] = os.environ) -> str:
    """The variable this distro's Fast DDS reads (``ROS_DISTRO``; unset: the newer name)."""
    return PROFILE_VARS[0] if environ.get('ROS_DISTRO', '') in FAST_DDS_2 else PROFILE_VARS[1]


def profile_path(directory: Optional[Path] = None) -> Optional[Path]:
    """The installed (or source tree's) profile file, or None."""
    if directory is None:
        from .graph import config_dir
        try:
            directory = config_dir()
        except FileNotFoundError:
            return None
    p = Path(directory) / PROFILE_FILE
    return p if p.is_file() else None


def startup_profile_env(environ: Mapping[str, str] = os.environ, cwd: Optional[Path] = None,
                        directory: Optional[Path] = None) -> Dict[str, str]:
    """The variable to add to ``environ`` so that Fast DDS loads the start's profile
    (:func:`profile_var` = its path), or {} when the RMW is not Fast DDS or the user has a profile
    of their own (either name, or a default file in ``cwd``: theirs wins, untouched)."""
    rmw = environ.get('RMW_IMPLEMENTATION', '')
    if rmw and not rmw.startswith('rmw_fastrtps'):
        return {}
    if any(environ.get(v) for v in PROFILE_VARS):
        return {}
    here = Path.cwd() if cwd is None else Path(cwd)
    if any((here / f).is_file() for f in CWD_PROFILES):
        return {}
    path = profile_path(directory)
    return {profile_var(environ): str(path)} if path is not None else {}


def use_startup_profile(environ=os.environ) -> Dict[str, str]:
    """Add :func:`startup_profile_env` to ``environ`` (this process and the ones it starts;
    before its first DDS participant). Returns what was added."""
    add = startup_profile_env(environ)
    environ.update(add)
    return add
