from setuptools import find_packages, setup

package_name = 'kinect_experiments'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    tests_require=['pytest'],
    zip_safe=True,
    maintainer='Kinect Posture Team',
    maintainer_email='robotics@example.com',
    description='Evaluation and experiment tools: accuracy tables, real-data LOSO, benchmarks, soak, '
                'fuzzing, the generated parameter reference.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'evaluate = kinect_experiments.evaluate:main',
            'bench = kinect_experiments.bench:main',
            'soak = kinect_experiments.soak:main',
            'passthrough = kinect_experiments.passthrough:main',
            'param_docs = kinect_experiments.param_docs:main',
            'compare_results = kinect_experiments.compare_results:main',
        ],
    },
)
