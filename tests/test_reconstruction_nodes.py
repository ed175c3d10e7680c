"""The reliability, completion and optimizer nodes over real DDS: a corrupted synthetic clip is
published on /kinect/skeletons and the reconstructed postures must be closer to the truth than the
raw ones; parameters are validated at run time; malformed input is dropped, not fatal."""
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy')

from ros_helpers import Spinner, wait_until as _wait  # noqa: E402
from skeleton_core.rosnode import bring_up  # noqa: E402


@pytest.fixture(scope='module')
def case():
    from pose_reconstruction.synthetic import scenario
    return scenario(frames=60)


def test_pipeline_over_dds(rclpy_context, case):
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from pose_reconstruction.completion_node import CompletionNode
    from pose_reconstruction.optimizer_node import OptimizerNode
    from pose_reconstruction.posture_space import parent_relative_error
    from pose_reconstruction.reliability_node import ReliabilityNode
    from skeleton_core.conversions import (SkeletonFrame, frames_from_array_msg,
                                           frames_to_array_msg)
    from skeleton_msgs.msg import SkeletonArray

    db, truth, obs, ts = case
    ctx = rclpy_context
    # private topic names (remapped through the input/output_topic parameters), so that other
    # DDS traffic on the same domain cannot reach this test
    ns = f'/t{os.getpid()}'
    t_in, t_rel = ns + '/kinect/skeletons', ns + '/kinect/skeletons_reliability'
    t_comp, t_rec = ns + '/posture/completed', ns + '/posture/reconstructed'

    def topics(i, o):
        return [Parameter('input_topic', value=i), Parameter('output_topic', value=o)]
    nodes = [ReliabilityNode(context=ctx, parameter_overrides=topics(t_in, t_rel)),
             CompletionNode(database_obj=db, context=ctx,
                            parameter_overrides=topics(t_rel, t_comp)),
             OptimizerNode(database_obj=db, context=ctx,
                           parameter_overrides=topics(t_rel, t_rec))]
    bring_up(*nodes)   # configure, then activate (lifecycle nodes)
    client = Node('test_client', context=ctx)
    got = {t_rel: {}, t_comp: {}, t_rec: {}}
    headers = []
    lock = threading.Lock()

    def make_cb(topic):
        def cb(msg):
            with lock:
                headers.append((topic, msg.header.stamp.sec, msg.header.stamp.nanosec,
                                msg.header.frame_id))
                for f in frames_from_array_msg(msg):
                    got[topic][f.stamp_ns] = f
        return cb

    subs = [client.create_subscription(SkeletonArray, t, make_cb(t), 100) for t in got]  # noqa
    pub = client.create_publisher(SkeletonArray, t_in, 100)
    spinner = Spinner(ctx, *nodes, client)
    try:
        assert _wait(lambda: pub.get_subscription_count() >= 1 and all(
            client.count_publishers(t) >= 1 for t in got), 10.0)
        time.sleep(0.3)
        t0 = 1_700_000_000_000_000_000
        stamps = []
        for i in range(len(obs)):
            stamp = t0 + i * 33_333_333
            stamps.append(stamp)
            f = SkeletonFrame(positions=obs[i], tracking_state=ts[i], user_id=4, stamp_ns=stamp,
                              frame_id='kinect_depth')
            pub.publish(frames_to_array_msg([f], stamp, 'kinect_depth'))
            # lock-step (the machine may be loaded): the next frame once this one came out
            _wait(lambda stamp=stamp: all(stamp in v for v in got.values()), 3.0, step=0.002)
        assert _wait(lambda: all(len(v) >= len(obs) for v in got.values()), 10.0), \
            ({k: len(v) for k, v in got.items()}, [n.health.snapshot() for n in nodes])
        # a malformed skeleton (wrong joint count) and an out-of-order array are dropped
        bad = frames_to_array_msg([SkeletonFrame(positions=obs[0], tracking_state=ts[0],
                                                 user_id=5, stamp_ns=stamps[-1] + 1)],
                                  stamps[-1] + 1, 'kinect_depth')
        bad.skeletons[0].positions = bad.skeletons[0].positions[:5]
        pub.publish(bad)
        late = frames_to_array_msg([SkeletonFrame(positions=obs[0], tracking_state=ts[0],
                                                  user_id=4, stamp_ns=stamps[-1] - 10_000_000)],
                                   stamps[-1] - 10_000_000, 'kinect_depth')
        pub.publish(late)
        assert _wait(lambda: nodes[0].health.dropped.get('out-of-order stamp', 0) >= 1
                     and nodes[0].health.dropped.get('wrong length', 0) >= 1, 5.0), \
            dict(nodes[0].health.dropped)
        with lock:
            rel = np.array([got[t_rel][s].reliability for s in stamps])
            comp = np.array([got[t_comp][s].positions for s in stamps])
            rec_frames = [got[t_rec][s] for s in stamps]
        rec = np.array([f.positions for f in rec_frames])
        # stamps, user ids and frame ids survive the three nodes
        assert all(f.user_id == 4 and f.frame_id == 'kinect_depth' for f in rec_frames)
        assert {h[3] for h in headers} == {'kinect_depth'}
        # reliability filled in: the inferred, snapped-on left arm is unreliable while occluded
        assert np.all(np.isfinite(rel)) and rel[30:40, 7].max() < 0.2 and rel[:, 0].min() > 0.5
        raw = parent_relative_error(obs, truth)
        err_c = parent_relative_error(rec, truth)
        err_a = parent_relative_error(comp, truth)
        assert err_c < 0.8 * raw, (err_c, raw)
        assert err_a < raw, (err_a, raw)
        # parameters: validated at run time, out-of-range and inconsistent values refused
        opt = nodes[2]
        assert not opt.set_parameters([Parameter('k', value=0)])[0].successful
        assert not opt.set_parameters([Parameter('samples', value=0)])[0].successful
        assert not nodes[0].set_parameters([Parameter('user_timeout_s', value=0.0)])[0].successful
        assert opt.set_parameters([Parameter('method', value='B')])[0].successful
        assert not opt.set_parameters([Parameter('database', value='/nonexistent/db.npz')])[0].successful
    finally:
        spinner.stop()
        for n in nodes + [client]:
            n.destroy_node()


def test_missing_database_is_one_clear_error(tmp_path):
    import subprocess
    import sys
    bad = tmp_path / 'corrupt.npz'
    bad.write_bytes(b'not a database')
    for path in (str(tmp_path / 'missing.npz'), str(bad)):
        p = subprocess.run([sys.executable, '-m', 'pose_reconstruction.optimizer_node',
                            '--ros-args', '-p', f'database:={path}'],
                           capture_output=True, text=True, timeout=60)
        assert p.returncode == 1, p.stderr
        lines = [ln for ln in p.stderr.strip().splitlines() if ln.strip()]
        assert lines[-1].startswith('[ERROR]') and path in lines[-1], p.stderr
        # one line, from on_configure, naming the command that builds the file
        assert len([ln for ln in lines if '[ERROR]' in ln]) == 1, p.stderr
        assert 'make build-db' in lines[-1], p.stderr
        assert 'Traceback' not in p.stderr


_WARM_PROBE = """
import sys
import rclpy
from pose_reconstruction import kernels, reliability_kernels
from pose_reconstruction.{module} import {cls}
rclpy.init()
node = {cls}()
before = (reliability_kernels._warm, kernels._warm[0])
node.trigger_configure()
print(before, (reliability_kernels._warm, kernels._warm[0]))
node.destroy_node()
rclpy.try_shutdown()
"""


@pytest.mark.parametrize('module,cls', [('reconstruction_node', 'ReconstructionNode'),
                                        ('optimizer_node', 'OptimizerNode')])
def test_configure_loads_the_compiled_kernels_before_the_first_frame(module, cls):
    """Loading the kernels from numba's cache takes 0.5-0.7 s even on a quiet machine: on a
    user's first frame it stalled the node, and a rate-1 replay lost the frames behind it
    (frames 1-19 of 60, a depth-10 queue). Configure loads them (a fresh process: the flags are
    per process)."""
    import subprocess
    import sys
    from skeleton_core import jit
    if not jit.enabled():
        pytest.skip('numba off (KINECT_NUMBA=0): no compiled kernels to load')
    p = subprocess.run([sys.executable, '-c', _WARM_PROBE.format(module=module, cls=cls)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip().splitlines()[-1] == '(False, False) (True, True)', p.stdout + p.stderr


def test_state_per_user_dropped_after_timeout(rclpy_context, case):
    from rclpy.parameter import Parameter

    from rclpy.serialization import serialize_message

    from pose_reconstruction.reliability_node import ReliabilityNode
    from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg

    _, _, obs, ts = case
    node = bring_up(ReliabilityNode(context=rclpy_context, parameter_overrides=[
        Parameter('user_timeout_s', value=0.2),
        Parameter('input_topic', value=f'/t{os.getpid()}/unused_in'),
        Parameter('output_topic', value=f'/t{os.getpid()}/unused_out')]))
    try:
        def send(uids, stamp):
            frames = [SkeletonFrame(positions=obs[0], tracking_state=ts[0], user_id=u,
                                    stamp_ns=stamp) for u in uids]
            # the node subscribes serialized messages (raw=True): what DDS hands it
            node._on_msg(serialize_message(frames_to_array_msg(frames, stamp, 'k')))
        send([1, 2], 1_000)
        assert set(node._users) == {1, 2}
        time.sleep(0.3)
        send([2], 2_000)
        assert set(node._users) == {2}  # user 1 unseen for longer than user_timeout_s
        # a valid run-time change rebuilds every user's state; an invalid one is refused
        assert node.set_parameters([Parameter('user_timeout_s', value=0.25)])[0].successful
        assert node._users == {}
        assert not node.set_parameters([Parameter('user_timeout_s', value=0.0)])[0].successful
        assert not node.set_parameters([Parameter('input_topic', value='/x')])[0].successful
        # duplicate stamps are dropped and counted once per cause
        send([2], 3_000)
        send([2], 3_000)
        assert node.health.dropped['duplicate stamp'] == 1
        assert node.health.published == 3
    finally:
        node.destroy_node()


def test_methods_register_with_the_evaluation_harness(case):
    registry = pytest.importorskip('skeleton_eval.registry')
    import pose_reconstruction.methods as methods

    db = case[0]
    assert methods.register()
    for name in ('A', 'B', 'C'):
        assert name in registry.available_methods()
    m = methods.make_method_c(db=db, db_size=300, k=12, steps=5)
    assert m.name == 'C' and m.db.size == 300 and m.core.k == 12 and m.core.steps == 5
    with pytest.raises(ValueError):
        methods.make_method_b(db=db, no_such_parameter=1)


def test_config_files_hold_every_parameter_with_its_default():
    import yaml

    from pose_reconstruction import completion_node, node_common, optimizer_node
    from skeleton_core.params import public
    ROOT = Path(__file__).resolve().parents[1]
    common = node_common.common_specs('', '')
    for name, specs in (('reliability', common + node_common.RELIABILITY_SPECS),
                        ('completion', common + completion_node.SPECS
                         + node_common.RELIABILITY_SPECS),
                        ('optimizer', common + optimizer_node.SPECS
                         + node_common.RELIABILITY_SPECS + node_common.CORRECTION_SPECS)):
        values = yaml.safe_load((ROOT / 'config' / f'{name}.yaml').read_text())
        values = values['/**']['ros__parameters']
        specs = public(specs)
        assert set(values) == {s.name for s in specs}, name
        for s in specs:
            if s.name not in ('input_topic', 'output_topic'):
                assert values[s.name] == s.default, (name, s.name)


def test_fused_parameters_map_the_three_config_files():
    from kinect_bringup.graph import load_params
    from pose_reconstruction import reconstruction_node as rn
    from skeleton_core.params import public

    fused = rn.fused_parameters(load_params('reliability'), load_params('completion'),
                                load_params('optimizer'))
    specs = {s.name: s for s in public(rn.PARAMS)}
    # every public parameter but the topics comes from the split nodes' files with their values
    assert set(fused) == set(specs) - {'input_topic', 'output_topic', 'reliability_topic',
                                       'completed_topic'}
    assert fused['optimizer.k'] == load_params('optimizer')['k']
    # one reliable_threshold for both methods (the split nodes' files hold one each)
    assert fused['reliable_threshold'] == load_params('optimizer')['reliable_threshold'] == \
        load_params('completion')['reliable_threshold']
    assert not any(k.startswith('reliability.') for k in specs)   # fixed (presets only)
    for k, v in fused.items():  # and the files hold the specs' defaults
        assert specs[k].default == v, k
    assert rn.section(fused, 'optimizer')['method'] == 'C'
    every = {s.name for s in rn.PARAMS}
    assert 'optimizer.database' not in every and 'completion.use_input_reliability' not in every
    assert 'optimizer.reliable_threshold' not in every and 'completion.reliable_threshold' \
        not in every


def test_fused_node_over_dds(rclpy_context, case):
    """The one-node reconstruction: same outputs as the three nodes from /kinect/skeletons;
    the completion is computed only while /posture/completed has a subscriber."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from pose_reconstruction.posture_space import parent_relative_error
    from pose_reconstruction.reconstruction_node import ReconstructionNode
    from skeleton_core.conversions import (SkeletonFrame, frames_from_array_msg,
                                           frames_to_array_msg)
    from skeleton_msgs.msg import SkeletonArray

    db, truth, obs, ts = case
    ctx = rclpy_context
    ns = f'/f{os.getpid()}'
    t_in, t_rel = ns + '/kinect/skeletons', ns + '/kinect/skeletons_reliability'
    t_comp, t_rec = ns + '/posture/completed', ns + '/posture/reconstructed'
    node = ReconstructionNode(database_obj=db, context=ctx, parameter_overrides=[
        Parameter('input_topic', value=t_in), Parameter('output_topic', value=t_rec),
        Parameter('reliability_topic', value=t_rel), Parameter('completed_topic', value=t_comp)])
    bring_up(node)
    client = Node('fused_client', context=ctx)
    got = {t_rel: {}, t_comp: {}, t_rec: {}}
    lock = threading.Lock()

    def make_cb(topic):
        def cb(msg):
            with lock:
                for f in frames_from_array_msg(msg):
                    got[topic][f.stamp_ns] = f
        return cb

    subs = {t: client.create_subscription(SkeletonArray, t, make_cb(t), 100)
            for t in (t_rel, t_rec)}
    pub = client.create_publisher(SkeletonArray, t_in, 100)
    spinner = Spinner(ctx, node, client)
    t0 = 1_700_000_000_000_000_000

    def send(i):
        stamp = t0 + i * 33_333_333
        f = SkeletonFrame(positions=obs[i], tracking_state=ts[i], user_id=4, stamp_ns=stamp,
                          frame_id='kinect_depth')
        pub.publish(frames_to_array_msg([f], stamp, 'kinect_depth'))
        return stamp

    try:
        assert _wait(lambda: pub.get_subscription_count() >= 1 and all(
            client.count_publishers(t) >= 1 for t in subs), 10.0)
        time.sleep(0.3)
        # nobody subscribes to the completion yet: not computed, not published
        for i in range(10):
            s = send(i)
            assert _wait(lambda s=s: s in got[t_rec] and s in got[t_rel], 3.0, step=0.002)
        assert node._users[4].comp is None and not got[t_comp]
        subs[t_comp] = client.create_subscription(SkeletonArray, t_comp, make_cb(t_comp), 100)
        assert _wait(lambda: node._pubs[2].get_subscription_count() >= 1, 10.0)
        stamps = []
        for i in range(10, len(obs)):
            s = send(i)
            stamps.append(s)
            _wait(lambda s=s: all(s in v for v in got.values()), 3.0, step=0.002)
        assert _wait(lambda: all(s in got[t] for s in stamps for t in got), 10.0), \
            ({k: len(v) for k, v in got.items()}, node.health.snapshot())
        with lock:
            rec_frames = [got[t_rec][s] for s in stamps]
            rel = np.array([got[t_rel][s].reliability for s in stamps])
            comp = np.array([got[t_comp][s].positions for s in stamps])
        rec = np.array([f.positions for f in rec_frames])
        assert all(f.user_id == 4 and f.frame_id == 'kinect_depth' for f in rec_frames)
        # the reliability output is the one the optimizer used
        assert np.array_equal(rel, np.array([f.reliability for f in rec_frames]))
        assert rel[30 - 10:40 - 10, 7].max() < 0.2 and rel[:, 0].min() > 0.5
        raw = parent_relative_error(obs[10:], truth[10:])
        assert parent_relative_error(rec, truth[10:]) < 0.8 * raw
        assert parent_relative_error(comp, truth[10:]) < raw
        # prefixed parameters: validated, and a change reaches the library objects
        assert not node.set_parameters([Parameter('optimizer.k', value=0)])[0].successful
        assert not node.set_parameters(
            [Parameter('reliable_threshold', value=1.5)])[0].successful
        assert node.set_parameters([Parameter('optimizer.k', value=12)])[0].successful
        assert node._users == {}
        assert node.make_processor(dict(node.params.values)).rec.core.k == 12
    finally:
        spinner.stop()
        for n in (node, client):
            n.destroy_node()


def test_a_parameter_the_node_does_not_declare_is_refused_by_name(rclpy_context):
    """rclpy ignores an override of an undeclared parameter: a removed or misspelt name in a YAML
    file or -p would change nothing without a word. The nodes refuse it in one line, and say
    when the name is a library value set only by a preset."""
    from rclpy.parameter import Parameter

    from pose_reconstruction.reliability_node import ReliabilityNode
    with pytest.raises(ValueError, match=r"'theta_floor_deg' is not a parameter of node "
                                         r"'reliability' \(a fixed value .* preset"):
        ReliabilityNode(context=rclpy_context,
                        parameter_overrides=[Parameter('theta_floor_deg', value=100.0)])
    with pytest.raises(ValueError, match=r"'user_timeout' is not a parameter .*misspelt"):
        ReliabilityNode(context=rclpy_context,
                        parameter_overrides=[Parameter('user_timeout', value=1.0)])


def test_reconstruction_diagnostics_report_each_users_bone_lengths(rclpy_context, case):
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message

    from pose_reconstruction.reconstruction_node import ReconstructionNode
    from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg
    from skeleton_core.model import NUM_SEGMENTS

    db, _, obs, ts = case
    node = bring_up(ReconstructionNode(database_obj=db, context=rclpy_context,
                                       parameter_overrides=[
        Parameter('input_topic', value=f'/t{os.getpid()}/rec_in'),
        Parameter('output_topic', value=f'/t{os.getpid()}/rec_out')]))
    try:
        def send(k):
            i = k if k < len(obs) else 2 * len(obs) - 1 - k   # the clip forth and back
            f = SkeletonFrame(positions=obs[i], tracking_state=ts[i], user_id=7,
                              stamp_ns=1_000_000 + k * 33_333_333)
            node._on_msg(serialize_message(frames_to_array_msg([f], f.stamp_ns, 'k')))
        send(0)
        assert node.diagnostics_extra()['user_7_bone_lengths_m'] == 'estimating'
        for k in range(1, 100):   # frozen at the latest 2 s after the first trusted frame
            send(k)
        d = node.diagnostics_extra()
        text = d['user_7_bone_lengths_m']
        pairs = dict(kv.split('=') for kv in text.split())
        assert len(pairs) == NUM_SEGMENTS and 'HipCenter-Spine' in pairs
        rec = node._users[7].rec
        assert np.allclose([float(v) for v in pairs.values()], rec.bone_lengths, atol=1e-4)
        assert d['user_7_bone_length_restarts'] == 0
    finally:
        node.destroy_node()


def test_reconstruction_node_processes_a_messages_users_together(rclpy_context, case):
    """Messages of three users (the node solves their optimizer runs together): every user's
    output equals its own FusedProcessor's, frame by frame; a message with one user goes the
    one-user way; a user with a malformed skeleton is dropped alone."""
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message

    from pose_reconstruction.fused import FusedProcessor
    from pose_reconstruction.reconstruction_node import ReconstructionNode
    from skeleton_core.cdr import frames_from_cdr
    from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg

    db, _, obs, ts = case
    node = bring_up(ReconstructionNode(database_obj=db, context=rclpy_context,
                                       parameter_overrides=[
        Parameter('input_topic', value=f'/t{os.getpid()}/batch_in'),
        Parameter('output_topic', value=f'/t{os.getpid()}/batch_out')]))
    sent = []
    node._pubs[0].publish = sent.append   # the serialized output, without DDS
    refs = {}
    try:
        for k in range(30):
            stamp = 1_000_000 + k * 33_333_333
            uids = (3,) if k == 5 else (1, 2, 3)
            frames = [SkeletonFrame(positions=obs[k] + (0.7 * u, 0.0, 0.0),
                                    tracking_state=ts[(k + 7 * u) % len(ts)], user_id=u,
                                    stamp_ns=stamp) for u in uids]
            msg = frames_to_array_msg(frames, stamp, 'k')
            if k == 12:   # user 2's skeleton malformed: dropped at decoding, the others kept
                msg.skeletons[1].positions = msg.skeletons[1].positions[:10]
                frames = [f for f in frames if f.user_id != 2]
            node._on_msg(serialize_message(msg))
            _, _, out = frames_from_cdr(sent[-1], [])
            assert [f.user_id for f in out] == [f.user_id for f in frames]
            for f, o in zip(frames, out):
                ref = refs.setdefault(f.user_id, FusedProcessor(db, dict(node.params.values)))
                r = ref.process(f, (True, False, False))[0]
                np.testing.assert_allclose(o.positions, r.positions, rtol=0, atol=1e-9)
        assert sum(node.health.dropped.values()) == 1   # user 2's skeleton in message 12
    finally:
        node.destroy_node()
