def make_controller(task)
    return None
