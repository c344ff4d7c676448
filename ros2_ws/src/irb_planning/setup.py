from glob import glob

from setuptools import find_packages, setup

package_name = 'irb_planning'

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
    description=('Energy-optimal motion planning along a path (CasADi) and its baselines '
                 'for the IRB 1600.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'planner = irb_planning.planner_node:main',
            'plan = irb_planning.plan_cli:main',
            'place = irb_planning.place_cli:main',
            'cycle = irb_planning.cycle_cli:main',
            'plan6 = irb_planning.plan6_cli:main',
        ],
    },
)
