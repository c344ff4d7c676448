from glob import glob

from setuptools import find_packages, setup

package_name = 'irb_identification'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'README.md']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='IRB stack maintainers',
    maintainer_email='maintainers@irb-stack.dev',
    description=(
        'MCAP recording, replay, friction identification and the model-discrepancy '
        'workflow for the IRB 1600.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'recorder = irb_identification.recorder_node:main',
            'replay = irb_identification.replay_node:main',
            'identify = irb_identification.identify:main',
            'import_log = irb_identification.import_log:main',
            'identifier = irb_identification.identifier_node:main',
            'experiments = irb_identification.experiments:main',
            'discrepancy = irb_identification.discrepancy:main',
            'excite = irb_identification.excite:main',
            'breakaway = irb_identification.breakaway_cli:main',
        ],
    },
)
