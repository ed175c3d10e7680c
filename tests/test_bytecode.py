"""make setup writes the workspace's bytecode (kinect_bringup.bytecode, run by warm_kernels), so
that no process of the first start compiles a module of the install or a launch file."""
import os
import py_compile

from kinect_bringup import bytecode


def test_stale_until_compiled_and_again_after_an_edit(tmp_path):
    pkg = tmp_path / 'pkg'
    pkg.mkdir()
    mod = pkg / 'mod.py'
    mod.write_text('X = 1\n')
    launch = tmp_path / 'share'
    launch.mkdir()
    lf = launch / 'graph.launch.py'
    lf.write_text('Y = 2\n')
    files = bytecode.sources([pkg], [launch])
    assert files == sorted([mod, lf])
    assert bytecode.stale(files) == files
    for f in files:
        py_compile.compile(str(f))
    assert bytecode.stale(files) == []
    mod.write_text('X = 10\n')   # another size: the pyc no longer matches
    assert bytecode.stale(files) == [mod]
    st = lf.stat()
    os.utime(lf, (st.st_atime, st.st_mtime + 5))   # another mtime
    assert bytecode.stale(files) == sorted([mod, lf])


def test_workspace_has_no_uncompiled_module_after_compile():
    packages, launch = bytecode.workspace_dirs()
    names = {p.name for p in packages}
    assert {'kinect_bringup', 'pose_reconstruction', 'physics_sim', 'skeleton_core'} <= names
    assert any((d / 'pipeline.launch.py').exists() for d in launch)
    bytecode.compile_workspace()
    files = bytecode.sources(packages, launch)
    assert len(files) > 100
    assert bytecode.stale(files) == []
