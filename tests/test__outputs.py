"""The output paths of a command checked before its work (:mod:`jaxbpm._outputs`)."""

import os

import pytest

from jaxbpm._outputs import OutputPathError, check_outputs, is_data_file
from jaxbpm.errors import JaxbpmError


def test_output_that_is_an_input_is_refused_even_with_force(tmp_path):
    sample = tmp_path / "s.h5"
    sample.write_bytes(b"\x89HDF\r\n\x1a\nrest")
    for path in (sample, tmp_path / "." / "s.h5", tmp_path / "sub" / ".." / "s.h5"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        with pytest.raises(OutputPathError, match=r"--history .*input SAMPLE.*not even with --force"):
            check_outputs({"--history": path}, {"SAMPLE": sample}, force=True)
    link = tmp_path / "link.h5"
    os.link(sample, link)  # another name of the same file: os.path.samefile
    with pytest.raises(OutputPathError, match="input SAMPLE"):
        check_outputs({"--out": link}, {"SAMPLE": sample}, force=True)
    with pytest.raises(OutputPathError, match="runs_file .*input SAMPLE"):  # a resumed file is no input either
        check_outputs({}, {"SAMPLE": sample}, resumable={"runs_file": sample})


def test_two_outputs_naming_one_file_are_refused(tmp_path):
    with pytest.raises(OutputPathError, match="name the same file"):
        check_outputs({"--history": tmp_path / "h.h5", "runs": tmp_path / "x" / ".." / "h.h5"}, {}, force=True)
    (tmp_path / "x").mkdir()
    with pytest.raises(OutputPathError, match="name the same file"):
        check_outputs({"--history": tmp_path / "h.h5"}, {}, resumable={"runs_file": tmp_path / "h.h5"})


def test_existing_sample_or_record_needs_force(tmp_path):
    hdf5 = tmp_path / "record.out"  # HDF5 by content, whatever the suffix
    hdf5.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(16))
    data = tmp_path / "s.data"
    data.write_text("LAMMPS data file\n")
    view = tmp_path / "s.vtu"
    view.write_text("<VTKFile/>")
    assert is_data_file(hdf5) and is_data_file(data) and not is_data_file(view)
    assert not is_data_file(tmp_path / "missing.h5") and not is_data_file(tmp_path)
    for path in (hdf5, data):
        with pytest.raises(OutputPathError, match=r"--out .*exists.*--force") as err:
            check_outputs({"--out": path}, {})
        assert isinstance(err.value, JaxbpmError) and isinstance(err.value, OSError) and str(path) in str(err.value)
        check_outputs({"--out": path}, {}, force=True)
    check_outputs({"OUT": view}, {})  # a view of a sample (VTU) is replaced freely
    check_outputs({"--out": tmp_path / "new.h5", "--history": None}, {"SAMPLE": None})


def test_unwritable_output_is_refused(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such directory"):
        check_outputs({"--out": tmp_path / "missing" / "a.h5"}, {})
    with pytest.raises(IsADirectoryError):
        check_outputs({"--out": tmp_path}, {}, force=True)
