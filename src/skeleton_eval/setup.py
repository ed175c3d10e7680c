from setuptools import find_packages, setup

package_name = 'skeleton_eval'

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
    description='Offline evaluation: sensor model, metrics, evaluation harness, paired real data, registration, calibration.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'import_uiprmd = skeleton_eval.uiprmd_cli:main',
        ],
    },
)
