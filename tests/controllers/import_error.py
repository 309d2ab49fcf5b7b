import hexbench_module_that_does_not_exist  # noqa: F401


def make_controller(task):
    return None
