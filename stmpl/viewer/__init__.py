"""Press and see: ``stmpl view``, a local web app in which a person drags an object over a body
and watches a predictor's answer, its time and its verdict (inside its data, outside with the
reason, or past where the gel buckles) as they move.

:mod:`~stmpl.viewer.press` turns what the person chose (an object, a place, a force) into a
:class:`~stmpl.scene.Scene`; :mod:`~stmpl.viewer.mailbox` answers only the latest of the
requests that arrive while a predictor is busy; :mod:`~stmpl.viewer.tiles` sends the browser
only the pieces of the surface that changed; :mod:`~stmpl.viewer.legend` writes the colour scale
and the verdict; :mod:`~stmpl.viewer.app` wires them to a `viser <https://viser.studio>`_ server
(its three.js client ships in the wheel: nothing is fetched from the network).
"""
