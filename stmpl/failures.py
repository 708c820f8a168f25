"""What can go wrong with an answer, as warnings and errors a caller can catch (a light module:
the command line names them before anything heavy is imported).
"""


class ImpossibleAnswer(RuntimeWarning):
    """A prediction moved the skin further inward than the FEM itself answers on the gel
    (:data:`stmpl.tissue.GEL_TRUSTED_COMPRESSION` of the tissue's thickness, where the gel
    buckles; through the fixed surface beneath at worst): flagged
    (``Deformation.info["physical"]``) and warned about, never passed off as an answer.
    """


class OutsideEnvelope(RuntimeWarning):
    """A scene lies outside the data a predictor's answers are backed by (its
    :class:`~stmpl.envelope.Envelope`): answered, flagged (``Deformation.info["envelope"]``) and
    warned about once per call; with ``strict=True`` refused instead.
    """


class PredictionFailed(RuntimeError):
    """A predictor could not answer a scene (e.g. a FEM solve that did not converge); the message
    says why. Never returned as a result.
    """
