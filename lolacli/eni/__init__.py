"""ENI model and parser (pure: strings and bytes in, values out).

``parse_eni(data, source)`` builds an :class:`~lolacli.eni.model.Eni`; file reading lives in
:func:`lolacli.files.load_eni`. :mod:`lolacli.eni.validate`, :mod:`lolacli.eni.diff` and
:mod:`lolacli.eni.report` work on the model.
"""

from lolacli.eni.model import Eni
from lolacli.eni.parser import parse_eni

__all__ = ["Eni", "parse_eni"]
