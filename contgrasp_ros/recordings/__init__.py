"""What is done with a recording after the run: offline analysis (``contgrasp analyze``) and
replay (``contgrasp bag replay``); writing and reading MCAP is :mod:`contgrasp_ros.bag`."""
