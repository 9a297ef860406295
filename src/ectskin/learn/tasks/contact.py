"""Contact: where, how hard and how many fingers touch, and whether one hovers (:class:`ContactTask`).

Data: :func:`ectskin.learn.data.contact.contact_dataset` (per-frame ground truth of the twin or
of an import with contact labels); model: :class:`~ectskin.learn.models.contact.ContactNet`.

Training loss (:class:`ContactCriterion`), per frame:

* cross-entropy of the finger count (0, 1, 2), each count weighted by √(1 / its frequency)
  (:func:`count_weights`: two fingers are rare);
* frames with no finger on the skin: binary cross-entropy of hover;
* frames with fingers: per finger, cross-entropy of its face, smooth-L1 of its (u, v) (in units
  of the face's half extent, weight :data:`POSITION_WEIGHT`) and of its force (in units of the
  training force scale), and the Gaussian negative log-likelihood of the position under the
  predicted variance (with the position itself held fixed, so the variance learns the error
  without pulling the point), and the same for the force under its predicted variance (a model
  with ``force_sigma``; the force itself held fixed, so its smooth-L1 fit is what it was
  without the variance, and the variance's minimiser is the expected squared force error given
  the window). One finger is slot 0; two are matched to the slots in the cheaper of the two
  orders (permutation-invariant).

Augmentation: the inflation shift, and the finger mix (``settings.finger_mix``, the
probability that a window with one finger on the skin takes another finger's signal, hovering
or touching: :mod:`ectskin.learn.tasks.contact_mix`).

Validation metric: the mean distance (mm) between each finger's true and predicted points,
slot 0 for one finger, matched for two; a wrong face is charged the body's thickness across.
The validation pass also calibrates the force's σ on those held-out frames (a model with
``force_sigma``): the variance the training frames taught is scaled so that the mean of
(force error / σ)² over the validation frames with one finger is 1, and the scale is stored in
the model (``force_sigma_scale``), so the weights kept for an epoch carry their own epoch's
scale. A network's errors on frames it trained on are smaller than on others; without the scale
its σ would be too small on new frames.
Test localisation errors are distances over the skin (:func:`ectskin.layout.geometry.on_skin_distance`:
around the body's side edge between front and back). Test metrics: localisation (mean / median / p90, per face,
per inflation state, a map per face, and split by where the other finger is:
``by_other_finger``), force, hover detection against height, finger count and
per-finger error after Hungarian matching, the calibration of the force's σ (the share of
frames within ±1σ and ±2σ), each beside the baselines of
:mod:`ectskin.learn.baselines.contact` on the same test frames. :func:`force_split_report` splits
the force error by a per-frame bound (the reproduction's, :mod:`ectskin.pipeline.bound`).
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, ClassVar

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ectskin._check import EctskinError
from ectskin.io import Recording
from ectskin.layout.geometry import on_skin_distance
from ectskin.learn.augment import no_contact_means
from ectskin.learn.baselines.contact import contact_baselines, left_out
from ectskin.learn.data.contact import (
    CONTACT_SPLIT,
    HOVER_MAX_MM,
    MAX_FINGERS,
    ContactData,
    contact_dataset,
)
from ectskin.learn.engine import Tensors
from ectskin.learn.metrics.contact import (
    force_coverage,
    force_metrics,
    force_split,
    hover_metrics,
    localisation_metrics,
    multi_metrics,
    other_finger_split,
    rest_points,
)
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS, ContactNet, ContactNetConfig
from ectskin.learn.normalizer import Normalizer
from ectskin.learn.predict.base import forward_batches
from ectskin.learn.profiles import TrainSettings
from ectskin.learn.tasks.base import Criterion, EvalCase, Task, as_tensor, build_config
from ectskin.learn.tasks.contact_mix import (
    MIX_FAR_MM,
    MIX_HOVER_MAX_MM,
    FingerSignals,
    finger_signals,
    mix_fingers,
)
from ectskin.viz.contact import plot_error_maps, plot_force_scatter, plot_hover_curve

#: windows per batch when predicting a test split
PREDICT_BATCH = 4096
#: weight of the position term against the cross-entropies
POSITION_WEIGHT = 10.0
#: smooth-L1 transition of the position and force terms (normalised units)
SMOOTH_BETA = 0.02
#: weight of each Gaussian negative log-likelihood (of the point's and of the force's variance)
NLL_WEIGHT = 0.1


def slot_columns(pred: np.ndarray, slot: int) -> dict[str, np.ndarray]:
    """The columns of finger slot ``slot`` of a prediction array, by name."""
    a = len(PRED_COLUMNS) + slot * len(SLOT_COLUMNS)
    return {name: pred[:, a + k] for k, name in enumerate(SLOT_COLUMNS)}


class ContactCriterion(Criterion):
    """See the module docstring. ``thickness`` (mm) charges a wrong face in the metric;
    ``state_means`` (n_states, P) the inflation shift's no-contact means; ``signals`` the finger
    mix's (:func:`~ectskin.learn.tasks.contact_mix.finger_signals`), which a window with one
    finger on the skin takes with probability ``finger_mix``."""

    def __init__(
        self,
        model: nn.Module,
        thickness_mm: float,
        state_means: torch.Tensor | None = None,
        count_weight: torch.Tensor | None = None,
        signals: FingerSignals | None = None,
        finger_mix: float = 0.0,
    ) -> None:
        super().__init__()
        if not (np.isfinite(finger_mix) and 0.0 <= finger_mix <= 1.0):
            raise EctskinError(f"finger_mix must be a probability in [0, 1], got {finger_mix!r}")
        mixes = signals is not None and len(signals) > 0 and finger_mix > 0
        self.signals = signals if mixes else None
        self.finger_mix = float(finger_mix) if mixes else 0.0
        self.thickness = float(thickness_mm)
        # the model whose force σ the validation pass calibrates (None: one without the σ)
        net = getattr(model, "module", model)
        self.sigma_model = net if hasattr(net, "force_sigma_scale") else None
        self.count_weight = count_weight  # (S + 1,) or None: every count weighs 1
        self.state_means = state_means  # (n_states, P) or None: no inflation shift
        self.shift_states = 0 if state_means is None else len(state_means)

    @property
    def augments(self) -> bool:
        return self.state_means is not None or self.signals is not None

    @staticmethod
    def _finger_loss(out, s: int, face, uv_n, f_n) -> torch.Tensor:
        """(B,) loss of slot ``s`` against one finger (face (B,), uv_n (B, 2), f_n (B,))."""
        ce = F.cross_entropy(out["face"][:, s], face.clamp_min(0), reduction="none")
        pos = F.smooth_l1_loss(out["uv"][:, s], uv_n, reduction="none", beta=SMOOTH_BETA).sum(-1)
        lv = out["log_var"][:, s]
        err2 = (out["uv"][:, s].detach() - uv_n).square().sum(-1)
        nll = 0.5 * (2 * lv + err2 * torch.exp(-lv))
        force = F.smooth_l1_loss(out["force"][:, s], f_n, reduction="none", beta=SMOOTH_BETA)
        if "force_log_var" in out:  # the force's variance, its mean held fixed
            flv = out["force_log_var"][:, s]
            nll = nll + 0.5 * (flv + (out["force"][:, s].detach() - f_n).square() * torch.exp(-flv))
        return ce + POSITION_WEIGHT * pos + NLL_WEIGHT * nll + force

    def _targets(self, model: nn.Module, face, uv, force):
        m = getattr(model, "module", model)
        f = face.clamp_min(0)
        uv_n = (uv - m.uv_centre[f]) / m.uv_half[f]  # (B, S, 2)
        return uv_n, force / m.force_scale

    def _per_sample(self, model: nn.Module, batch) -> tuple[torch.Tensor, dict]:
        x, count, face, uv, force, hover = batch
        out = model(x)
        loss = F.cross_entropy(out["count"], count, reduction="none")
        if self.count_weight is not None:
            loss = loss * self.count_weight[count]
        off = count == 0
        bce = F.binary_cross_entropy_with_logits(out["hover"], hover, reduction="none")
        loss = loss + torch.where(off, bce, torch.zeros_like(bce))
        uv_n, f_n = self._targets(model, face, uv, force)
        straight = sum(
            self._finger_loss(out, s, face[:, s], uv_n[:, s], f_n[:, s]) for s in range(2)
        )
        swapped = sum(
            self._finger_loss(out, s, face[:, 1 - s], uv_n[:, 1 - s], f_n[:, 1 - s])
            for s in range(2)
        )
        one = self._finger_loss(out, 0, face[:, 0], uv_n[:, 0], f_n[:, 0])
        fingers = torch.where(count >= 2, torch.minimum(straight, swapped), one)
        loss = loss + torch.where(count > 0, fingers, torch.zeros_like(fingers))
        return loss, out

    def loss(self, model, batch, rng):
        if rng is not None and self.signals is not None:  # the finger mix, then the shift
            batch = mix_fingers(batch, self.signals, self.finger_mix, rng)
        if rng is not None and self.state_means is not None:
            # the inflation shift: the same window seen at another inflation, as the difference
            # of the no-contact means of two training states drawn at random
            x, *rest = batch
            ab = torch.from_numpy(rng.integers(0, len(self.state_means), size=(2, len(x))))
            shift = self.state_means[ab[0].to(x.device)] - self.state_means[ab[1].to(x.device)]
            batch = (x + shift[:, None, :], *rest)
        return self._per_sample(model, batch)[0].mean()

    def _distance(self, model, out, batch) -> tuple[torch.Tensor, torch.Tensor]:
        """Summed finger distance (mm) and finger count of ``batch``."""
        _, count, face, uv, _, _ = batch
        m = getattr(model, "module", model)
        pf = out["face"].argmax(-1)  # (B, S)
        p_uv = m.uv_centre[pf] + out["uv"] * m.uv_half[pf]

        def dist(s, j):
            d2 = (p_uv[:, s] - uv[:, j]).square().sum(-1)
            wrong = (pf[:, s] != face[:, j]).to(d2.dtype)
            return torch.sqrt(d2 + wrong * self.thickness**2)

        two = torch.minimum(dist(0, 0) + dist(1, 1), dist(0, 1) + dist(1, 0))
        per = torch.where(
            count >= 2, two, torch.where(count == 1, dist(0, 0), torch.zeros_like(two))
        )
        return per.sum(), count.clamp_max(2).sum().to(per.dtype)

    def eval_sums(self, model, batch) -> torch.Tensor:
        loss, out = self._per_sample(model, batch)
        dist, n_fingers = self._distance(model, out, batch)
        z2, n_one = loss.new_zeros(()), loss.new_zeros(())
        if "force_log_var" in out:  # (force error / σ)² of slot 0 on frames with one finger
            _, count, face, uv, force, _ = batch
            _, f_n = self._targets(model, face, uv, force)
            one = count == 1
            r2 = (out["force"][:, 0] - f_n[:, 0]).square() * torch.exp(-out["force_log_var"][:, 0])
            z2, n_one = r2[one].sum(), one.sum().to(loss.dtype)
        return torch.stack([loss.sum(), dist, n_fingers, loss.new_tensor(len(loss)), z2, n_one])

    def finish(self, sums: torch.Tensor) -> tuple[float, float]:
        """(val_loss, val_metric); sets the force σ's scale of the model (module docstring)."""
        loss, dist, n_fingers, n, z2, n_one = sums.tolist()
        if self.sigma_model is not None and n_one > 0 and np.isfinite(z2):
            self.sigma_model.force_sigma_scale.fill_(float(np.sqrt(max(z2 / n_one, 1e-12))))
        return loss / n, dist / max(n_fingers, 1.0)


class ContactTask(Task[ContactData]):
    """Contact (see the module docstring): :class:`ContactData` → :class:`ContactNet`."""

    name = "contact"
    model_kind = ContactNet.kind
    data_type = "ContactData"
    arrays = ("x", "count", "face", "uv", "force", "hover")
    batch_fields = ("x", "count", "face", "uv", "force", "hover")
    metric_name = "loc_mm"
    lower_is_better_metric = True
    split_counts = CONTACT_SPLIT
    figure_captions: ClassVar[dict[str, str]] = {
        "contact_error_map": "Contact localisation error over each face (mean mm per 5 mm cell)",
        "contact_force": "Contact force: predicted against true, test frames in contact",
        "contact_hover": "Hover detection rate against the finger's height",
    }

    # ------------------------------------------------------------------ data
    def check_options(self, *, window: int, prior: bool) -> None:
        if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
            raise EctskinError(f"window must be an integer >= 1 (frames), got {window!r}")
        if not prior:
            raise EctskinError(
                "the prior option applies to 'track' only, got prior=False for 'contact'"
            )

    def dataset(
        self, rec: Recording, *, window: int = 10, prior: bool = True, reference: Any = "auto"
    ) -> ContactData:
        return contact_dataset(rec, window=window, reference=reference)

    def dataset_options(self, config: ContactNetConfig) -> dict[str, Any]:
        return {"window": int(config.window)}

    def stratify(self, data: ContactData) -> np.ndarray | None:
        return data.group_region if len(data.group_region) else None

    def _check_shapes(self, data: ContactData, what: str) -> None:
        n = data.x.shape[0]
        s = MAX_FINGERS
        want = {"count": (n,), "face": (n, s), "uv": (n, s, 2), "force": (n, s), "hover": (n,)}
        if data.x.ndim != 3:
            raise EctskinError(
                f"{what}: contact data must have x (n, k, n_pairs), got {data.x.shape}"
            )
        for name, shape in want.items():
            got = getattr(data, name).shape
            if got != shape:
                raise EctskinError(f"{what}: contact {name} must have shape {shape}, got {got}")
        bad = (data.count < 0) | (data.count > s)
        if bad.any():
            raise EctskinError(f"{what}: finger count must be 0..{s}, got {data.count[bad][0]}")

    def tensors(self, data: ContactData, device: torch.device) -> Tensors:
        return Tensors(
            (
                as_tensor(data.x, np.float32, device),
                as_tensor(data.count, np.int64, device),
                as_tensor(data.face, np.int64, device),
                as_tensor(data.uv, np.float32, device),
                as_tensor(data.force, np.float32, device),
                as_tensor(data.hover, np.float32, device),
            )
        )

    # ------------------------------------------------------------------ model
    def build_model(self, data: ContactData, model_options: dict[str, Any] | None) -> ContactNet:
        shape = {
            "n_pairs": int(data.x.shape[2]),
            "window": int(data.x.shape[1]),
            "n_faces": len(data.faces),
            "max_fingers": MAX_FINGERS,
        }
        # new models give the force's σ (model option force_sigma=False builds one without)
        options = {"force_sigma": True, **(model_options or {})}
        return ContactNet(build_config(ContactNetConfig, shape, options))

    def fit_normalization(self, model: nn.Module, data: ContactData) -> dict[str, Any]:
        """Per-pair mean / std of the training windows; each face's centre and half extent
        (from the layout's skins); the force scale (the mean force of training frames in
        contact, 1 N without any)."""
        norm = Normalizer.fit(data.x)
        centre = np.array(
            [[np.mean(data.face_extent[f][0]), np.mean(data.face_extent[f][1])] for f in data.faces]
        )
        half = np.array(
            [
                [np.ptp(data.face_extent[f][0]) / 2, np.ptp(data.face_extent[f][1]) / 2]
                for f in data.faces
            ]
        )
        on = data.count > 0
        scale = float(data.force[on, 0].mean()) if on.any() else 1.0
        model.set_normalization(
            norm.mean, norm.std, centre, np.maximum(half, 1e-3), max(scale, 1e-3)
        )
        return {
            "x": norm.to_dict(),
            "uv_centre": centre.tolist(),
            "uv_half": half.tolist(),
            "force_scale": scale,
        }

    def checkpoint_extra(self, data: ContactData) -> dict[str, Any]:
        return {
            "faces": list(data.faces),
            "face_extent": {f: [list(a), list(b)] for f, (a, b) in data.face_extent.items()},
            "hover_max_mm": HOVER_MAX_MM,
        }

    # ------------------------------------------------------------------ training
    def criterion(
        self, model, settings: TrainSettings, train_data: ContactData, device
    ) -> ContactCriterion:
        """With ``settings.inflation_shift``, the no-contact means (last frame of each window) of
        the training split's no-contact trials (at least two, else skipped with a note); with
        ``settings.finger_mix`` > 0, the training split's finger signals
        (:func:`~ectskin.learn.tasks.contact_mix.finger_signals`; none: skipped with a note)."""
        state_means, notes = None, []
        if settings.inflation_shift:
            frames = SimpleNamespace(
                x=train_data.x[:, -1, :],
                group=train_data.group,
                group_region=train_data.group_region,
            )
            means = no_contact_means(frames)
            if len(means) >= 2:
                state_means = torch.from_numpy(means).to(device)
            else:
                notes.append(
                    f"inflation shift skipped: the training data holds {len(means)} no-contact "
                    "trial(s), at least 2 are needed"
                )
        finger_mix, signals = float(settings.finger_mix), None
        if finger_mix > 0:
            signals = finger_signals(train_data).to(device)
            if not len(signals):
                signals = None
                notes.append(
                    "finger mix skipped: the training data holds no trial that starts with its "
                    f"finger at least {MIX_FAR_MM:g} mm away and then hovers within "
                    f"{MIX_HOVER_MAX_MM:g} mm of the skin and touches it"
                )
        criterion = ContactCriterion(
            model,
            train_data.body_mm[1],
            state_means,
            count_weights(train_data.count).to(device),
            signals=signals,
            finger_mix=finger_mix,
        )
        criterion.notes.extend(notes)
        return criterion

    # ------------------------------------------------------------------ evaluation
    def predict(self, model: nn.Module, data: ContactData) -> np.ndarray:
        """(n, 3 + S · 6) float32 predictions: :data:`PRED_COLUMNS`, then per slot
        :data:`SLOT_COLUMNS`."""
        m = getattr(model, "module", model)
        return forward_batches(model, [data.x], batch_size=PREDICT_BATCH, output=m.decode)

    def test_metrics(self, case: EvalCase[ContactData]) -> dict[str, Any]:
        m = contact_report(case.test, case.pred)
        m["window"] = int(case.config.window)
        m["arch"] = getattr(case.config, "arch", None)  # None: a classical model
        return m

    def baseline_metrics(
        self, train: ContactData, test: ContactData, *, seed: int
    ) -> dict[str, Any]:
        out = {}
        for name, (pred, seconds) in contact_baselines(
            train, test, train.region_centre, seed=seed
        ).items():
            m = contact_report(test, pred, with_maps=False)
            m["fit_s"] = seconds
            out[name] = m
        return out

    def baselines_left_out(self, train: ContactData) -> dict[str, str]:
        return left_out(train)

    def figures(self, case: EvalCase[ContactData], metrics: dict[str, Any]) -> dict[str, Any]:
        test, pred = case.test, case.pred
        single = test.count == 1
        p0 = slot_columns(pred, 0)
        return {
            "contact_error_map": plot_error_maps(metrics["map"], test.face_extent),
            "contact_force": plot_force_scatter(test.force[single, 0], p0["force_n"][single]),
            "contact_hover": plot_hover_curve(
                metrics["hover"]["curve"], metrics["hover"]["rate_threshold"]
            ),
        }


def count_weights(count: np.ndarray) -> torch.Tensor:
    """(S + 1,) weights of the finger counts in the training loss: √(n / ((S + 1) n_c)), so that a
    rare count (two fingers are on the skin in a few percent of the frames) is not simply never
    predicted; 1 for a count the data does not hold. The square root keeps the common counts'
    accuracy (full inverse-frequency weights trade too much of it)."""
    n_c = np.bincount(np.asarray(count, np.int64), minlength=MAX_FINGERS + 1).astype(np.float64)
    w = np.ones(MAX_FINGERS + 1)
    present = n_c > 0
    w[present] = np.sqrt(n_c.sum() / (present.sum() * n_c[present]))
    return torch.from_numpy(w.astype(np.float32))


def _state_name(state: tuple[float, ...]) -> str:
    return "/".join(f"{v:g}" for v in state) + " ml" if state else "-"


def slot_points(test: ContactData, pred: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per frame and finger slot, of the truth in ``test`` and of predictions ``pred`` (columns
    of :meth:`ContactTask.predict`): (true face (n, S), predicted face (n, S), predicted (u, v)
    (n, S, 2), true and predicted rest points (n, S, 3), :func:`rest_points` on ``test``'s
    body)."""
    width, thickness = test.body_mm
    faces = list(test.faces)
    p_face = np.stack([slot_columns(pred, s)["face"] for s in range(MAX_FINGERS)], 1).astype(int)
    p_uv = np.stack(
        [
            np.column_stack([slot_columns(pred, s)["u_mm"], slot_columns(pred, s)["v_mm"]])
            for s in range(MAX_FINGERS)
        ],
        1,
    )
    t_face = np.clip(test.face, 0, None)
    true_pts = rest_points(faces, t_face, test.uv, width_mm=width, thickness_mm=thickness)
    pred_pts = rest_points(
        faces, np.clip(p_face, 0, len(faces) - 1), p_uv, width_mm=width, thickness_mm=thickness
    )
    return t_face, p_face, p_uv, true_pts, pred_pts


def point_errors(data: ContactData, pred: np.ndarray) -> np.ndarray:
    """(n,) mm, per frame of ``data`` with one finger on the skin (``data.count == 1``, in row
    order): the distance over the skin between the true point and the point of ``pred``'s first
    finger slot (prediction columns, :meth:`ectskin.learn.tasks.contact.ContactTask.predict`; a
    predicted face outside the data's is taken as the nearest of them). Their mean is
    ``contact_report(data, pred)["loc_mm_mean"]``."""
    pred = np.asarray(pred, dtype=np.float64)
    ncol = len(PRED_COLUMNS) + MAX_FINGERS * len(SLOT_COLUMNS)
    if pred.shape != (data.n_samples, ncol):
        raise EctskinError(f"point_errors: pred must have shape ({data.n_samples}, {ncol}) (one "
                           f"row per sample of data), got {pred.shape}")
    width, thickness = data.body_mm
    faces = list(data.faces)
    t_face, p_face, p_uv, _, _ = slot_points(data, pred)
    single = data.count == 1
    out = np.empty(int(single.sum()))
    tf, pf = t_face[single, 0], np.clip(p_face[single, 0], 0, len(faces) - 1)
    tuv, puv = data.uv[single, 0], p_uv[single, 0]
    for a in range(len(faces)):
        for b in range(len(faces)):
            m = (tf == a) & (pf == b)
            if m.any():
                out[m] = on_skin_distance(faces[a], tuv[m], faces[b], puv[m], width, thickness)
    return out


def contact_report(
    test: ContactData, pred: np.ndarray, *, with_maps: bool = True
) -> dict[str, Any]:
    """Every contact metric of predictions ``pred`` (columns of :meth:`ContactTask.predict`) on
    ``test``; the map arrays (for the figure) only ``with_maps``."""
    width, thickness = test.body_mm
    faces = list(test.faces)
    n = test.n_samples
    t_face, p_face, p_uv, true_pts, pred_pts = slot_points(test, pred)
    single = test.count == 1
    over_skin = point_errors(test, pred)
    state_names = [_state_name(s) for s in test.states]
    loc = localisation_metrics(
        true_pts[single, 0],
        pred_pts[single, 0],
        true_face=t_face[single, 0],
        pred_face=p_face[single, 0],
        faces=faces,
        state=test.state[single],
        state_names=state_names,
        true_uv=test.uv[single, 0] if with_maps else None,
        face_extent=test.face_extent if with_maps else None,
        distance=over_skin,
    )
    p0 = slot_columns(pred, 0)
    force = force_metrics(test.force[single, 0], p0["force_n"][single])
    coverage = force_coverage(
        test.force[single, 0], p0["force_n"][single], p0["force_sigma_n"][single]
    )
    force.update({k: v for k, v in coverage.items() if k != "n_frames"})
    force["n_frames_with_sigma"] = coverage["n_frames"]
    off = test.count == 0
    hover = hover_metrics(
        test.height[off],
        test.hover[off] > 0.5,
        pred[off, PRED_COLUMNS.index("p_hover")] > 0.5,
        finger_present=np.isfinite(test.height[off]),
        hover_max_mm=HOVER_MAX_MM,
    )
    count_pred = pred[:, PRED_COLUMNS.index("count")].astype(int)
    multi = multi_metrics(test.count, count_pred, true_pts, pred_pts, MAX_FINGERS)
    detect_true = test.count > 0
    detect_pred = count_pred > 0
    out: dict[str, Any] = {
        **{k: loc[k] for k in ("loc_mm_mean", "loc_mm_median", "loc_mm_p90", "face_accuracy")},
        "n_single_contact_frames": int(single.sum()),
        "force_mae_n": force["force_mae_n"],
        "force_rel": force.get("force_rel"),
        "force_coverage_1sigma": force["force_coverage_1sigma"],
        "force_coverage_2sigma": force["force_coverage_2sigma"],
        "force_sigma_n_median": force["force_sigma_n_median"],
        "hover_detect_mm": hover["hover_detect_mm"],
        "contact_accuracy": float(np.mean(detect_true == detect_pred)) if n else None,
        "count_accuracy": multi["count_accuracy"],
        "per_face": loc["per_face"],
        "per_state": loc.get("per_state", {}),
        "by_other_finger": other_finger_split(
            over_skin,
            test.other_height[single],
            HOVER_MAX_MM,
            state=test.state[single],
            state_names=state_names,
        ),
        "force": force,
        "hover": hover,
        "multi": multi,
        "sigma_mm_median": (
            float(np.nanmedian(p0["sigma_mm"][single]))
            if single.any() and np.isfinite(p0["sigma_mm"]).any()
            else None
        ),
    }
    if with_maps and "map" in loc:
        out["map"] = loc["map"]
    return out


def force_split_report(
    test: ContactData, pred: np.ndarray, bound_sd_n: np.ndarray, threshold_n: float
) -> dict[str, Any]:
    """The force error of predictions ``pred`` on ``test``'s frames with one finger on the skin
    (those of ``force_mae_n``), split by ``bound_sd_n`` (n,) N, the bound on the force's
    standard deviation at each sample's true point (NaN: none), at ``threshold_n``
    (:func:`ectskin.learn.metrics.contact.force_split`, with the coverage of the predicted σ)."""
    bound = np.asarray(bound_sd_n, float)
    if bound.shape != (test.n_samples,):
        raise EctskinError(
            f"force_split_report: bound_sd_n must have shape ({test.n_samples},), got {bound.shape}"
        )
    single = test.count == 1
    p0 = slot_columns(pred, 0)
    return force_split(
        test.force[single, 0],
        p0["force_n"][single],
        bound[single],
        threshold_n,
        sigma_n=p0["force_sigma_n"][single],
    )
