"""Preloaded by each worker of the batch engine (:mod:`gripper_ros.core.runtime.engine`).

``LocalCluster(preload=...)`` and ``dask worker --preload gripper_ros.core.runtime.batch_worker``
import this module as the worker starts: it loads the compiled core from numba's cache (and
the DMC models of the default configuration) by running one short grasp, so that the worker's
first task does not pay about a second for it.
"""
from gripper_ros.core.runtime.headless import warm_up_worker

warm_up_worker()
