"""Write the sensor-model variants of docs/multi_sensor.md (issue 31 (a)) to out/params/*.yaml:
noise (jitter, slow drift, systematic offsets), the profile angle and the occlusion capsules,
each x0.5 and x1.5."""
import os
import yaml
from skeleton_eval.sensor_params import DEFAULT_PARAMS as D


def scaled(group, f):
    return {k: v * f for k, v in group.items()}


os.makedirs('out/params', exist_ok=True)
for f, tag in ((0.5, 'x0.5'), (1.5, 'x1.5')):
    variants = {
        f'noise{tag}': {'jitter': {'base_mm': scaled(D['jitter']['base_mm'], f)},
                        'slow_drift': {'sigma_mm': scaled(D['slow_drift']['sigma_mm'], f)},
                        'systematic': {'sigma_mm': scaled(D['systematic']['sigma_mm'], f)}},
        f'profile{tag}': {'turn': {'degrade_deg': D['turn']['degrade_deg'] * f}},
        f'radius{tag}': {'occlusion_geometry': {
            'radius_scale': D['occlusion_geometry']['radius_scale'] * f}}}
    for k, v in variants.items():
        with open(f'out/params/{k}.yaml', 'w') as fh:
            yaml.safe_dump(v, fh)
