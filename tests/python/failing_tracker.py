"""Trackers that misbehave, for the Python plug-in's error paths."""


class Raising:
    def __init__(self, camera, options):
        self.fail_init = options.get("fail_init", False)
        if self.fail_init:
            raise KeyError("no such option")

    def process_frame(self, seq, timestamp, ids, u, v):
        if seq == 2:
            raise ZeroDivisionError("tracker divided by zero")
        if seq == 3:
            return "ok", None
        if seq == 4:
            return "flying", None
        return "lost", None
