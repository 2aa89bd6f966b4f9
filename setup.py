"""ament_python / pip setup for skidsteer_power."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'skidsteer_power'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'benchmarks', 'tools', 'tools.*']),
    package_data={PACKAGE: ['py.typed', 'data/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config/terrains', glob('config/terrains/*.yaml')),
        (f'share/{PACKAGE}/config/vehicles', glob('config/vehicles/*.yaml')),
        (f'share/{PACKAGE}/config/powertrains', glob('config/powertrains/*.yaml')),
        (f'share/{PACKAGE}/config/batteries', glob('config/batteries/*.yaml')),
        (f'share/{PACKAGE}/config/joints', glob('config/joints/*.yaml')),
        (f'share/{PACKAGE}/config/foxglove', glob('config/foxglove/*.json')),
        (f'share/{PACKAGE}/config', glob('config/*.yaml')),
        (f'share/{PACKAGE}/launch', glob('launch/*.launch.py')),
    ],
    python_requires='>=3.10',
    install_requires=[
        'setuptools',
        'numpy',
        'scipy',
        'PyYAML',
        'pyserial',
        'rosbags',
        'mcap',
        'rich',
        'matplotlib',
        'foxglove-sdk',
        'websockets>=13',
        'dask[distributed]',
        'SALib',
    ],
    zip_safe=True,
    maintainer='skidsteer_power developers',
    maintainer_email='skidsteer-power@example.com',
    description='Locomotion power and energy of skid-steered robots on deformable terrain.',
    license='Apache-2.0',
    extras_require={'test': ['pytest', 'hypothesis']},
    entry_points={
        'console_scripts': [
            'skidsteer-power = skidsteer_power.cli.main:main',
            'des_driver = skidsteer_power.nodes.des_driver:main',
            'power_estimator = skidsteer_power.nodes.power_estimator:main',
            'energy_monitor = skidsteer_power.nodes.energy_monitor:main',
        ],
    },
)
