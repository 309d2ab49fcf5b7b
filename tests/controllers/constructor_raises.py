def make_controller(task):
    raise RuntimeError("weights not found")
