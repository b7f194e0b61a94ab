"""The choice of model after a linear fit of free decays: the amplitude score tests, the
model-error term and the score statistics they share.
"""

from ._amplitude import MODELS as MODELS
from ._amplitude import P_FALSE as P_FALSE
from ._amplitude import amplitude_test as amplitude_test
from ._amplitude import choose_model as choose_model
from ._model_error import model_error as model_error
