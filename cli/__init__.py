"""The `vtdslam` command line: the composition root, so it alone may reach both the api and the worker."""
