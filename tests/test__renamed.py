"""The deprecated ``chunk=`` keyword: the value of ``batch_size=``, a warning, and an error when both are given."""

import warnings

import pytest

from jaxbpm._renamed import batch_size_keyword


def test_batch_size_is_taken_as_given_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert batch_size_keyword(4, None) == 4
        assert batch_size_keyword(None, None) is None


def test_chunk_gives_its_value_with_a_warning_naming_batch_size():
    with pytest.warns(DeprecationWarning, match="batch_size="):
        assert batch_size_keyword(None, 3) == 3


def test_both_is_a_type_error():
    with pytest.raises(TypeError, match="batch_size= only"):
        batch_size_keyword(2, 2)
