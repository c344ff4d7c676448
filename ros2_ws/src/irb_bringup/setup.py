from glob import glob

from setuptools import find_packages, setup

package_name = 'irb_bringup'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'README.md']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='IRB stack maintainers',
    maintainer_email='maintainers@irb-stack.dev',
    description=(
        'Bring-up of the IRB 1600 node graph, the main job (thesis pipeline) and its report.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'thesis_run = irb_bringup.thesis_run:main',
            'bringup = irb_bringup.bringup:main',
            'ctl = irb_bringup.ctl:main',
            'report = irb_bringup.report:main',
            'cycle_run = irb_bringup.cycle_run:main',
        ],
    },
)
