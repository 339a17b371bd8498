"""tprf: transient (time-of-flight) radiosity rendering from Python.

    import tprf
    scene = tprf.load_scene("meshes/corner.json")          # or a dict in the scene-file format
    print(tprf.info(scene)["estimate"]["peak_bytes"])
    result = tprf.render(scene, progress=lambda phase, f: print(phase, f))
    cube = result.transient                                # numpy float32 (H, W, T, 3), no copy

Bad input raises tprf.Error, a ValueError with the command line's message; Ctrl-C cancels a render
cleanly (KeyboardInterrupt). docs/python.md has the whole interface.
"""

from ._tprf import (Error, Result, Scene, __version__, apply_sensor, info, load_scene,  # noqa: F401
                    render)


def times(result_or_scene):
    """The start of every time bin, in the scene's time unit (metres of path or picoseconds)."""
    import numpy as np
    t = result_or_scene.time
    return t["start"] + t["bin_width"] * np.arange(t["bins"])


__all__ = ["Error", "Result", "Scene", "apply_sensor", "info", "load_scene", "render", "times", "__version__"]
