"""The viewer's web app: a body part drawn in a browser page, an object that follows the pointer
over the skin, and a predictor's answer, its time and its verdict after each move.

Every pointer event leaves a request in a one-slot mailbox (:class:`~stmpl.viewer.mailbox.Latest`):
only the latest is answered, so a slow answer never builds a queue; each answer sends only the
surface tiles that changed (:class:`~stmpl.viewer.tiles.Tiles`).
"""

from __future__ import annotations

import html
import io
import threading
import time
import warnings

import numpy as np
from scipy.spatial import cKDTree

from stmpl import tissue
from stmpl.body.mirror import counterpart
from stmpl.body.spec import part_from_spec
from stmpl.contact.hand import GRIPS
from stmpl.failures import ImpossibleAnswer, OutsideEnvelope
from stmpl.metrics import sample_metrics
from stmpl.pipeline.spec import label, predictor_from_spec
from stmpl.responsive import Responsive
from stmpl.viewer import legend
from stmpl.viewer.mailbox import Latest
from stmpl.viewer.press import OBJECTS, Choice, pressed
from stmpl.viewer.tiles import Tiles
from stmpl.viz.figures import mesh_bytes
from stmpl.viz.render import duration
from stmpl.viz.verdict import facts, verdict

OBJECT_COLOUR = (150, 190, 255)

BODIES = {
    "as started": {},
    "thin": {"weight": 0.1},
    "heavy": {"weight": 0.9},
    "muscular": {"muscle": 0.9},
    "short": {"height": 0.1},
    "tall": {"height": 0.9},
    "older": {"age": 0.9},
    "female": {"gender": 0.0},
    "male": {"gender": 1.0},
}
"""Anny bodies the page offers: changes to the phenotype the viewer started with (anny's
``weight``, ``muscle``, ``height``, ``age``, ``gender``, each in [0, 1])."""
TISSUES = ("paper", "forearm", "upper_arm", "abdomen")
"""The FEM's tissue presets (``fem.layers``): the paper's gel and the layered skin, fat and
muscle of three places. The learned models know the gel only; a layered tissue is the FEM's."""


def ray_hit(vertices: np.ndarray, faces: np.ndarray, origin, direction) -> int | None:
    """The vertex nearest to where the ray first meets the mesh (Moller-Trumbore over every
    face), or ``None`` if it misses.
    """
    o, d = np.asarray(origin, float), np.asarray(direction, float)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    if not hit.any():
        return None
    f = int(np.flatnonzero(hit)[np.argmin(t[hit])])
    point = o + t[f] * d
    corners = faces[f]
    return int(corners[np.argmin(np.linalg.norm(vertices[corners] - point, axis=1))])


def rotation(wxyz) -> np.ndarray:
    """``(3, 3)`` rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = wxyz
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def camera_ray(camera, screen) -> tuple[np.ndarray, np.ndarray]:
    """``(origin, direction)`` of the ray through screen point ``screen`` (OpenCV, 0..1 from
    the upper left) of a viser ``camera`` (``wxyz`` orientation: x right, y down, z ahead;
    ``fov`` vertical, rad; ``aspect`` width / height).
    """
    h = np.tan(0.5 * camera.fov)
    ahead = np.array([(2 * screen[0] - 1) * h * camera.aspect, (2 * screen[1] - 1) * h, 1.0])
    d = rotation(camera.wxyz) @ ahead
    return np.asarray(camera.position, float), d / np.linalg.norm(d)


def project(camera, point, width: int, height: int) -> tuple[float, float]:
    """Where ``point`` (m) shows on a page of ``width`` x ``height`` px through a viser
    ``camera``: the inverse of :func:`camera_ray` (a browser test's and a benchmark's aim).
    """
    p = rotation(camera.wxyz).T @ (np.asarray(point, float) - np.asarray(camera.position))
    f = 0.5 * height / np.tan(0.5 * camera.fov)
    return 0.5 * width + f * p[0] / p[2], 0.5 * height + f * p[1] / p[2]


class Viewer:
    """``stmpl view``: serve the app on ``host``:``port`` (127.0.0.1: this machine only).

    ``models``: predictor specs (``zoo:gnn_arm_bodies``, a checkpoint, ``linear``...), the
    first answering first; ``part``: the body part; ``phenotype``: anny's; ``thickness_mm``:
    the tissue (``None``: the paper's heuristic from the weight). With ``prepare``, before it
    serves, each predictor prepares the body (``Predictor.prepare``: a linear FEM prior's
    columns at every vertex, once per body and cached on disk; minutes the first time), with a
    progress bar unless ``progress`` is false; without, a press at a new place waits for its
    columns (seconds) the first time.
    """

    def __init__(
        self,
        models: list[str],
        part: str = "left_arm",
        phenotype: dict | None = None,
        thickness_mm: float | None = None,
        host: str = "127.0.0.1",
        port: int = 8080,
        device: str = "cpu",
        fidelity: str = "auto",
        prepare: bool = False,
        progress: bool = True,
    ):
        import viser  # deferred: the browser viewer only (its server and client)

        if not models:
            raise ValueError("the viewer needs at least one model to answer with")
        self.specs = list(models)
        self.predictors = {
            label(s): predictor_from_spec(s, device, fidelity=fidelity) for s in self.specs
        }
        first = next(iter(self.predictors.values()))
        skin = int(getattr(first, "part", None) and first.part.source.get("subdivisions", 0) or 0)
        self.part_name, self.phenotype, self.skin = part, dict(phenotype or {}), skin
        self.started = dict(self.phenotype)  # what the page's bodies change
        self.thickness_mm = thickness_mm
        self._body = threading.Lock()  # the body, its thickness and tiles change together
        self._build_part()
        for p in self.predictors.values():  # a viewer answers many presses: compiled loops
            p.load_kernels()
        if prepare:  # columns ahead: no press waits for the linear FEM
            for p in self.predictors.values():
                p.prepare(self.part, self.thickness, progress=progress)
        self.latencies: list[float] = []  # s, from the pointer event to the tiles sent
        self.tiles_sent = 0  # surface tiles sent since the start
        self.last = None  # (choice, scene, deformation, meshes, model) of the last answer shown
        self.objects: list = []  # (key of the mesh, its handle) per object mesh shown
        self._sending = threading.Lock()
        self.server = viser.ViserServer(host=host, port=port, label="stmpl", verbose=False)
        # soft studio light from a map that ships in viser's wheel; no shadows to speckle the skin
        self.server.scene.configure_environment_map(hdri="studio", environment_intensity=0.5)
        self.server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        self.server.scene.set_up_direction("+z")
        self._gui()
        self._draw_body()
        self.live = {  # a press at a new place: another model answers while this one prepares
            name: Responsive(p, [], True, self.request, self._say_error, name)
            for name, p in self.predictors.items()
        }
        for name, r in self.live.items():
            r.stand_ins = [other for o, other in self.live.items() if o != name]
        self.mailbox = Latest(self._answer, self._show)
        self.server.on_client_connect(self._welcome)
        self.request()

    # -- the body ---------------------------------------------------------------------------
    def _build_part(self) -> None:
        spec = {"model": "anny", "subdivisions": self.skin, "phenotype": self.phenotype}
        part = part_from_spec(spec, self.part_name)
        if self.thickness_mm is None:
            thickness = tissue.from_weight(part, self.phenotype.get("weight", 0.5))
        else:
            thickness = tissue.constant(part, self.thickness_mm * 1e-3)
        with self._body:
            self.part, self.thickness = part, thickness
            self.tree = cKDTree(part.vertices)
            self.tiles = Tiles(part.vertices, part.faces, 16)
            if getattr(self, "vertex", None) is None or self.vertex >= part.n_vertices:
                self.vertex = int(
                    np.argmin(
                        np.linalg.norm(
                            part.vertices - part.vertices.mean(0) + [0.0, 0.05, 0.0], axis=1
                        )
                    )
                )

    def rebody(
        self,
        phenotype: dict | None = None,
        thickness_mm: float | None = None,
        part: str | None = None,
    ) -> None:
        """Another body (anny's ``phenotype``), tissue (``thickness_mm``; ``None``: from the
        weight) or ``part`` (the other side's): built again, drawn at rest, and the press
        answered on it.
        """
        if phenotype is not None:
            self.phenotype = dict(phenotype)
        self.thickness_mm = thickness_mm
        moved = part is not None and part != self.part_name
        if moved:  # the press stays at the same vertex: the other side's twin of it
            self.part_name = part
        self.status.content = "building the body..."
        self._build_part()
        self.last = None
        self._draw_body(look=moved)
        self.request()

    def _draw_body(self, look: bool = False) -> None:
        """The body at rest; with ``look``, every open page's camera turned to it too (another
        part).
        """
        centre = self.part.vertices.mean(axis=0)
        size = float(np.ptp(self.part.vertices, axis=0).max())
        at, eye = tuple(centre), tuple(centre + np.array([0.0, -0.85 * size, 0.15 * size]))
        cam = self.server.initial_camera
        cam.look_at, cam.position = at, eye
        for client in self.server.get_clients().values() if look else ():
            client.camera.look_at, client.camera.position = at, eye
        self.tiles.forget()
        rest = legend.colours(np.zeros(self.part.n_vertices), 1.0)
        self._send_tiles(self.part.vertices, rest)

    def _send_tiles(self, vertices: np.ndarray, colours: np.ndarray) -> int:
        with self._sending:  # the answers' thread and the FEM's both draw
            return self._send_changed(vertices, colours)

    def _send_changed(self, vertices: np.ndarray, colours: np.ndarray) -> int:
        import trimesh  # deferred: the viewer only

        changed = self.tiles.changed(vertices, colours)
        self.tiles_sent += len(changed)
        for k in changed:
            used, faces = self.tiles.groups[k]
            mesh = trimesh.Trimesh(
                vertices[used], faces, vertex_colors=colours[used], process=False
            )
            h = self.server.scene.add_mesh_trimesh(f"/body/tile{k:02d}", mesh)
            h.on_click(self._clicked)  # a node sent again is a new node: its callbacks too
            h.on_drag(self._dragged)
        return len(changed)

    # -- the page -----------------------------------------------------------------------------
    def _gui(self) -> None:
        g = self.server.gui
        g.configure_theme(control_width="large", dark_mode=False, show_logo=False)
        g.add_markdown(
            "**stmpl: press and see.** Click the skin, or drag on it, to move the object; "
            "the colours show how far the skin moves."
        )
        self.model = g.add_dropdown("predictor", list(self.predictors))
        self.kind = g.add_dropdown("object", list(OBJECTS), initial_value="disk")
        self.force = g.add_slider("force, N", 0.05, 5.0, 0.05, 0.3)
        self.radius = g.add_slider("radius, mm", 2.0, 40.0, 1.0, 20.0)
        self.grip = g.add_dropdown("grip", sorted(GRIPS), initial_value="whole", visible=False)
        self.upload = g.add_upload_button(
            "press your own mesh", hint="STL, OBJ, PLY or GLB, in mm or m"
        )
        self.verdict = g.add_html(legend.verdict_html("inside", "answering..."))
        self.scale = g.add_html(legend.colour_bar(1.0))
        self.status = g.add_html("")
        with g.add_folder("compare with the FEM", expand_by_default=False):
            self.compare = g.add_button("solve this press with the FEM")
            self.progress = g.add_progress_bar(0.0, visible=False, animated=True)
            self.compared = g.add_markdown("")
        with g.add_folder("save"):
            self.shot = g.add_button("screenshot (PNG)")
            self.save_glb = g.add_button("deformed mesh (GLB)")
            self.save_ply = g.add_button("deformed mesh (PLY)")
        with g.add_folder("body and tissue", expand_by_default=False):
            sides = [self.part_name] + [x for x in [counterpart(self.part_name)] if x]
            self.side = g.add_dropdown("part", sides, initial_value=self.part_name)
            self.body = g.add_dropdown("body", list(BODIES), initial_value="as started")
            mm = 1e3 * float(np.mean(self.thickness))
            self.depth = g.add_slider("tissue, mm", 2.5, 12.5, 0.25, round(4 * mm) / 4)
            self.tissue = g.add_dropdown("FEM's tissue", list(TISSUES), initial_value="paper")
            g.add_markdown(
                "The learned models know the paper's gel; a layered tissue is the FEM's "
                "(compare with the FEM)."
            )
        self.side.on_update(lambda _: self._body_changed(thickness=False))
        self.body.on_update(lambda _: self._body_changed(thickness=False))
        self.depth.on_update(lambda _: self._body_changed(thickness=True))
        self.mesh = None
        for h in (self.model, self.force, self.radius, self.grip):
            h.on_update(lambda _: self.request())
        self.kind.on_update(self._kind_changed)
        self.upload.on_upload(self._uploaded)
        self.compare.on_click(lambda e: self._compare())
        self.shot.on_click(self._screenshot)
        self.save_glb.on_click(lambda e: self._save(e, "glb"))
        self.save_ply.on_click(lambda e: self._save(e, "ply"))

    def _body_changed(self, thickness: bool) -> None:
        """A body from the page's list, or a tissue depth from its slider (until the slider is
        moved, a body's tissue follows its weight), built in the background.
        """
        phenotype = {**self.started, **BODIES[self.body.value]}
        mm = float(self.depth.value) if thickness else self.thickness_mm
        side = self.side.value
        if not thickness and phenotype == self.phenotype and side == self.part_name:
            return
        threading.Thread(
            target=self._rebody_safely, args=(phenotype, mm, side), name="stmpl-body", daemon=True
        ).start()

    def _rebody_safely(self, phenotype: dict, mm: float | None, side: str) -> None:
        try:
            self.rebody(phenotype, mm, side)
        except Exception as e:  # a body anny cannot build, a thickness out of range: said
            self._say_error(str(e).splitlines()[0] if str(e) else type(e).__name__)

    def _welcome(self, client) -> None:
        client.add_notification(
            "stmpl", "Click or drag on the skin to press.", auto_close_seconds=4.0
        )

    def _kind_changed(self, _) -> None:
        k = self.kind.value
        self.radius.visible = k in ("disk", "fingertip")
        self.grip.visible = k == "hand"
        if k == "fingertip" and self.radius.value > 15:
            self.radius.value = 8.0  # also requests
        elif k != "mesh" or self.mesh is not None:
            self.request()

    def _uploaded(self, event) -> None:
        import trimesh  # deferred: the viewer only

        f = event.target.value
        try:
            mesh = trimesh.load(
                io.BytesIO(f.content), file_type=f.name.rsplit(".", 1)[-1], force="mesh"
            )
            if len(mesh.faces) == 0:
                raise ValueError("it has no faces")
        except Exception as e:  # a file that is not a mesh: say so on the page
            self._say_error(f"{f.name} could not be read as a mesh: {e}")
            return
        if np.ptp(mesh.vertices, axis=0).max() > 1.0:  # mm, as most CAD files are
            mesh.apply_scale(1e-3)
        self.mesh = mesh
        if self.kind.value != "mesh":
            self.kind.value = "mesh"  # asks for an answer
        else:
            self.request()

    # -- pointer events -----------------------------------------------------------------------
    def _clicked(self, event) -> None:
        v = ray_hit(self.part.vertices, self.part.faces, event.ray_origin, event.ray_direction)
        if v is not None:
            self.vertex = v
            self.request()

    def _dragged(self, event) -> None:
        origin, direction = camera_ray(event.client.camera, event.end_screen_pos)
        v = ray_hit(self.part.vertices, self.part.faces, origin, direction)
        if v is None:  # off the skin: the nearest skin to the drag plane's point
            v = int(self.tree.query(np.asarray(event.end_position, float))[1])
        self.vertex = v
        self.request()

    def request(self) -> None:
        """Ask for an answer to the page's current choice (only the latest is answered)."""
        k = self.kind.value
        choice = dict(
            kind=k,
            vertex=self.vertex,
            force=float(self.force.value),
            radius_mm=float(self.radius.value),
            grip=self.grip.value,
            mesh=self.mesh,
        )
        self.mailbox.put((time.perf_counter(), self.model.value, choice))

    # -- answers ------------------------------------------------------------------------------
    def _answer(self, request):
        t0, name, kw = request
        choice = Choice(**kw)
        with self._body:
            part, thickness, phenotype = self.part, self.thickness, dict(self.phenotype)
        scene, meshes = pressed(part, thickness, choice, phenotype)
        with warnings.catch_warnings():  # said on the page instead
            warnings.simplefilter("ignore", OutsideEnvelope)
            warnings.simplefilter("ignore", ImpossibleAnswer)
            d = self.live[name].predict(scene)  # a stand-in's while its columns are solved
        return choice, scene, d, meshes

    @property
    def solving(self) -> list[str]:
        """The models being prepared for a place in the background."""
        return [name for name, r in self.live.items() if r.preparing]

    def _show(self, request, result) -> None:
        if isinstance(result, Exception):
            self._say_error(str(result).splitlines()[0] if str(result) else type(result).__name__)
            return
        t0, name, _ = request
        choice, scene, d, meshes = result
        if scene.part is not self.part:  # answered on a body the page has left
            return
        name = d.info.get("stand_in", {}).get("by", name)  # whose answer it is: saved so too
        self.last = (choice, scene, d, meshes, name)
        mag = d.magnitude * 1e3
        top = legend.scale_mm(float(mag.max()))
        colours = legend.colours(mag, top)
        sent = self._send_tiles(d.vertices, colours)
        self._send_objects(meshes)
        kind, words = verdict(d.info)
        self.verdict.content = legend.verdict_html(kind, words)
        self.scale.content = legend.colour_bar(top)
        self.latencies.append(time.perf_counter() - t0)
        self.status.content = (
            f'<div id="stmpl-answer" data-n="{len(self.latencies)}" style="font-size:0.9em">'
            f"<b>{html.escape(name)}</b>: deepest {mag.max():.2f} mm, answered in "
            f"{duration(d.info['seconds'])}; {choice.force:g} N on "
            f"{1e3 * float(np.mean(scene.thickness)):.3g} mm of tissue; {sent} of "
            f"{len(self.tiles)} surface tiles sent</div>"
        )
        self.server.flush()  # now, not at the next batch: the person is waiting

    def _send_objects(self, meshes: list) -> None:
        """Show the object's meshes, sending only those that moved or changed (a force slider
        moves nothing) and removing those no longer there (a hand's fingers, then a disk).
        """
        for k, m in enumerate(meshes):
            key = hash((np.asarray(m.vertices).tobytes(), np.asarray(m.faces).tobytes()))
            if k < len(self.objects) and self.objects[k][0] == key:
                continue
            h = self.server.scene.add_mesh_simple(
                f"/object/{k}", m.vertices, m.faces, color=OBJECT_COLOUR, opacity=0.25
            )
            if k < len(self.objects):
                self.objects[k] = (key, h)
            else:
                self.objects.append((key, h))
        for _, h in self.objects[len(meshes) :]:
            h.remove()
        del self.objects[len(meshes) :]

    def _say_error(self, text: str) -> None:
        self.verdict.content = legend.verdict_html("impossible", text)

    # -- the FEM, in the background -----------------------------------------------------------
    def _compare(self) -> None:
        if self.last is None:
            return
        choice, scene, d, _, name = self.last
        self.compare.disabled, self.progress.visible = True, True
        self.compared.content = "the FEM is solving this press (the page stays live)..."

        def solve() -> None:
            t0 = time.perf_counter()
            try:
                fem = predictor_from_spec(
                    "fem",
                    "cpu",
                    fidelity="auto",
                    tissue=self.tissue.value,
                    phenotype=self.phenotype,
                ).predict(scene)
                m = sample_metrics(fem.displacement, d.displacement)
                self.compared.content = (
                    f"FEM ({self.tissue.value}): deepest {fem.magnitude.max() * 1e3:.2f} mm in "
                    f"{duration(time.perf_counter() - t0)}; **{name}** against it: relative "
                    f"MEE {m['rel_mee']:.2f} %, peak {m['peak_err']:+.1f} %. The colours show "
                    "the error until the next press."
                )
                if self.last is not None and self.last[1] is scene:  # nothing pressed since
                    err = np.linalg.norm(d.displacement - fem.displacement, axis=1) * 1e3
                    top = legend.scale_mm(float(err.max()))
                    self._send_tiles(d.vertices, legend.colours(err, top))
                    self.scale.content = legend.colour_bar(
                        top, f"{name}'s error against the FEM, mm"
                    )
            except Exception as e:  # a failed solve says why, and nothing is shown as truth
                self.compared.content = f"the FEM could not solve this press: {e}"
            finally:
                self.compare.disabled, self.progress.visible = False, False

        threading.Thread(target=solve, name="stmpl-fem", daemon=True).start()

    # -- saving -------------------------------------------------------------------------------
    def _screenshot(self, event) -> None:
        import imageio.v3 as iio  # deferred: the viewer's screenshots

        image = event.client.get_render(height=720, width=1280, transport_format="png")
        png = iio.imwrite("<bytes>", image, extension=".png")
        event.client.send_file_download("stmpl_view.png", png, save_immediately=True)

    def _save(self, event, fmt: str) -> None:
        if self.last is None:
            return
        _, scene, d, _, name = self.last
        mesh = scene.part.mesh(d.vertices)
        mesh.visual.vertex_colors = legend.colours(
            d.magnitude * 1e3, legend.scale_mm(d.magnitude.max() * 1e3)
        )
        data = mesh_bytes(mesh, fmt, facts(d, name))  # the verdict travels with the mesh
        event.client.send_file_download(f"stmpl_pressed.{fmt}", data, save_immediately=True)

    def close(self) -> None:
        self.mailbox.close()
        self.server.stop()
