"""modules/cpp used from a user's own CMake project with add_subdirectory(), as the README says:
the library's target only, no example of its own beside the user's targets."""
from __future__ import annotations

import os
import subprocess

from tests.integration.test_cpp_modules import CPP


def _cmake(*cmd, timeout=900):
    out = subprocess.run(["cmake", *cmd], capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, "cmake %s:\n%s%s" % (" ".join(cmd), out.stdout[-4000:], out.stderr[-4000:])
    return out


def test_a_project_that_adds_the_library_may_name_its_own_module_gripper(tmp_path):
    """README's example name in the user's project: before, configuring failed with 'add_executable
    cannot create target "gripper" because another target with the same name already exists', and
    installing the project put bmtree's example into <prefix>/bin."""
    project = tmp_path / "my_robot"
    project.mkdir()
    (project / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.10)\nproject(my_robot CXX)\nset(CMAKE_CXX_STANDARD 14)\n"
        "add_subdirectory(%s bmtree_cpp)\n"
        "add_executable(gripper gripper.cpp)\n"
        "target_link_libraries(gripper PRIVATE bmtree_module)\n"
        "target_compile_options(gripper PRIVATE -Wall -Wextra -Werror)\n"
        "install(TARGETS gripper RUNTIME DESTINATION bin)\n" % CPP)
    with open(os.path.join(CPP, "example", "gripper.cpp")) as fh:
        (project / "gripper.cpp").write_text(fh.read())
    build, prefix = tmp_path / "build", tmp_path / "prefix"
    _cmake("-S", str(project), "-B", str(build))
    _cmake("--build", str(build))
    assert os.access(str(build / "gripper"), os.X_OK)            # the project's own
    assert not (build / "bmtree_cpp" / "gripper").exists()         # the library's example is not built
    _cmake("--install", str(build), "--prefix", str(prefix), timeout=300)
    assert sorted(os.listdir(str(prefix / "bin"))) == ["gripper"]
    assert (prefix / "bin" / "gripper").read_bytes() == (build / "gripper").read_bytes()  # the project's


def test_the_example_is_built_on_request_from_a_parent_project(tmp_path):
    """-DBMTREE_CPP_EXAMPLE=ON builds the example in a parent project that has no gripper of its own."""
    project = tmp_path / "parent"
    project.mkdir()
    (project / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.10)\nproject(parent CXX)\nadd_subdirectory(%s bmtree_cpp)\n" % CPP)
    build = tmp_path / "build"
    _cmake("-S", str(project), "-B", str(build), "-DBMTREE_CPP_EXAMPLE=ON", timeout=300)
    targets = _cmake("--build", str(build), "--target", "help", timeout=60).stdout
    assert "... gripper" in targets, targets
