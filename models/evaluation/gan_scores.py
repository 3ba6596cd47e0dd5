"""GAN-train and GAN-test accuracies (Shmelkov, Schmid, Alahari, "How good is my GAN?",
ECCV 2018), as Ferreira et al. (Computers & Graphics 2021, Table 3) report them for
dance: accuracies of the motion style classifier of :mod:`models.evaluation.classifier`.

* **GAN-test** = accuracy, on windows of the GENERATED validation motion (labelled
  with the style of the dance whose music made them), of the style classifier
  trained on REAL training-split motion (the one behind FD). High: the generated
  motion looks like its style to a judge that only saw real dances (realism and
  style fidelity).
* **GAN-train** = accuracy, on windows of the REAL validation motion, of a fresh
  style classifier (same architecture, epochs and seed) trained on motion GENERATED
  for the training-split songs (labelled by their dances' styles). High: the
  generated set is varied and faithful enough to stand in for real training data.

Both are window accuracies (64-frame windows, hop 32, :func:`classifier_windows`).
GAN-test uses the evaluation's classifier (the packaged one by default: the same on every
machine); GAN-train's classifier is trained afresh, so its value can differ with the
CPU's float kernels (:data:`models.evaluation.evaluate.PACKAGED_CLASSIFIER` says why).
For the real-data row both are the real classifier's accuracy on real validation
windows, the ceiling the two are read against. :func:`models.evaluation.evaluate.evaluate`
adds them as the optional keys ``gan_train`` and ``gan_test`` when
``EvalOptions.gan_scores`` is set (``performer evaluate --gan-scores``); GAN-train then
also generates every training-split dance, which costs about as much again as the
whole validation generation per training dance.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from models.errors import DataError
from models.evaluation.classifier import classifier_windows


def labelled_windows(positions: Sequence[np.ndarray], styles: Sequence[str],
                     class_names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Classifier windows of every sequence and the class index of its style."""
    xs, ys = [], []
    for p, s in zip(positions, styles):
        if s not in class_names:
            raise DataError(f"style {s!r} is not one the classifier knows ({list(class_names)})")
        w = classifier_windows([p])
        xs.append(w)
        ys.append(np.full(len(w), list(class_names).index(s), dtype=np.int64))
    x = np.concatenate(xs) if xs else np.zeros((0, 0, 0), np.float32)
    if len(x) == 0:
        raise DataError("no 64-frame classifier window in the sequences: they are too short")
    return x, np.concatenate(ys)


def accuracy(classifier, x: np.ndarray, y: np.ndarray) -> float:
    """Share of windows whose predicted class is their label."""
    from models.evaluation.classifier import predict

    return float(np.mean(predict(classifier, x) == y))


def gan_test(classifier, gen_pos: Sequence[np.ndarray], styles: Sequence[str]) -> float:
    """Accuracy of the real-trained ``classifier`` on generated motion (labels: the dances' styles)."""
    x, y = labelled_windows(gen_pos, styles, classifier.class_names)
    return accuracy(classifier, x, y)


def gan_train(gen_train_pos: Sequence[np.ndarray], gen_train_styles: Sequence[str],
              real_val_pos: Sequence[np.ndarray], real_val_styles: Sequence[str],
              class_names: Sequence[str], epochs: int = 10, seed: int = 0) -> float:
    """Accuracy on real validation motion of a classifier trained on generated training-song motion."""
    from models.evaluation.classifier import train_style_classifier

    x, y = labelled_windows(gen_train_pos, gen_train_styles, class_names)
    if len(np.unique(y)) < 2:
        raise DataError("GAN-train needs generated motion of at least 2 styles")
    model = train_style_classifier(x, y, epochs=epochs, seed=seed, class_names=list(class_names))
    xv, yv = labelled_windows(real_val_pos, real_val_styles, class_names)
    return accuracy(model, xv, yv)


def gan_scores(generate_train: Callable[[], list[np.ndarray]], train_styles: Sequence[str],
               gen_val_pos: Sequence[np.ndarray], real, classifier, epochs: int, seed: int) -> dict[str, float]:
    """``{"gan_train", "gan_test"}`` of one model.

    generate_train(): FK positions of the model's motion for every classifier-training
    dance (called once); ``real``: the evaluated :class:`~models.evaluation.evaluate.RealSet`.
    """
    val_styles = [c.style for c in real.clips]
    return {
        "gan_train": gan_train(generate_train(), train_styles, real.positions, val_styles,
                               classifier.class_names, epochs, seed),
        "gan_test": gan_test(classifier, gen_val_pos, val_styles),
    }


def real_reference(real, classifier) -> dict[str, float]:
    """The real-data row: the real classifier's accuracy on real validation windows, for both keys."""
    acc = gan_test(classifier, real.positions, [c.style for c in real.clips])
    return {"gan_train": acc, "gan_test": acc}
