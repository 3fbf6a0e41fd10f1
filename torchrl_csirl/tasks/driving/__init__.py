"""The four highway-env driving scenes (``highway-fast``, ``merge``, ``roundabout``, ``intersection``) and their expert.

* :mod:`~torchrl_csirl.tasks.driving.driving`: the scenes' gymnasium environments (ego route, goal, termination).
* :mod:`~torchrl_csirl.tasks.driving._road`, :mod:`~torchrl_csirl.tasks.driving._vehicles`,
  :mod:`~torchrl_csirl.tasks.driving._observation`: the road network, the traffic and the observation of a scene.
* :mod:`~torchrl_csirl.tasks.driving.expert_driver` (with :mod:`~torchrl_csirl.tasks.driving.expert_config`,
  :mod:`~torchrl_csirl.tasks.driving.route_follower`, :mod:`~torchrl_csirl.tasks.driving.road_clone`): the
  privileged expert driver; :mod:`~torchrl_csirl.tasks.driving.expert` gathers what drives it.

The scenes' specs are declared with every other task's in :mod:`torchrl_csirl.tasks.catalog`. This package's
``__init__`` imports none of its modules.
"""
