"""The web viewer (C++ module ``view``): the scene in a browser, in a notebook, or in one ``.html``.

The viewer is Spark (a Gaussian-splat renderer on three.js), installed from npm by
``bash scripts/web_viewer.sh`` (pinned; needs npm) and embedded in every page, so the pages open
offline. ``avsplat view SCENE`` serves it on 127.0.0.1; ``write_html`` (as ``avsplat convert
SCENE out.html``) writes a self-contained page; ``show`` puts the viewer in a Jupyter notebook.
The first frame follows the CPU renderer's 3DGS conventions from the given camera (default:
``default_camera``); dragging orbits, the wheel zooms.
"""

import html as _html
import os as _os
from typing import Any, Optional, Union

from ._avsplat import Camera, GaussianCloud, find_web_viewer, web_viewer_page, web_viewer_search_path, write_html

__all__ = ["find_web_viewer", "show", "web_viewer_page", "web_viewer_search_path", "write_html"]


def show(scene: Union[GaussianCloud, str, "_os.PathLike[str]"], camera: Optional[Camera] = None, *, height: int = 480,
         **options: Any) -> Any:
    """Show a scene inline in a Jupyter notebook, in the web viewer.

    The page of ``web_viewer_page`` goes into an ``<iframe srcdoc=...>`` of the notebook's
    width, so the notebook holds the scene (the saved notebook grows by about 4/3 of its PLY
    size plus the viewer's 3 MB).

    Parameters
    ----------
    scene : GaussianCloud or str or os.PathLike
        The Gaussians, or a file any reader of ``read_gaussians`` reads.
    camera : Camera, optional
        The initial view (default: ``default_camera(cloud)``).
    height : int
        The frame's height in pixels (> 0); the width follows the notebook.
    **options
        ``background``, ``up``, ``target``, ``title``, ``viewer_dir``: as ``web_viewer_page``.

    Returns
    -------
    IPython.display.HTML
        What was displayed (also returned so that it can be displayed again).

    Raises
    ------
    ImportError
        Without IPython.
    FileError
        When the viewer is not installed (the message says how) or the scene file cannot be read.
    """
    from IPython.display import HTML, display

    if int(height) <= 0:
        raise ValueError(f"height: must be > 0, got {height}")
    if not isinstance(scene, GaussianCloud):
        from ._avsplat import read_gaussians

        scene = read_gaussians(_os.fspath(scene))
    page = web_viewer_page(scene, camera, **options)
    # In a <div>: IPython's HTML warns about a bare <iframe> (IFrame takes a URL, not a page).
    frame = HTML(
        f'<div><iframe srcdoc="{_html.escape(page, quote=True)}" style="width: 100%; height: {int(height)}px; '
        'border: 0" allowfullscreen></iframe></div>'
    )
    display(frame)
    return frame
