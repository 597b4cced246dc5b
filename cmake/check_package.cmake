# The installed package, as a user meets it (run by CTest as library_package):
# install this build into a fresh prefix, run the installed program on a shipped scene,
# configure examples/library against it with find_package(dvm), build it and run it;
# with PYTHON (the interpreter the module is built for; empty: no module), import the
# installed Python package from PYTHON_DIR under the prefix and run a scene with it.
#   cmake -DBUILD_DIR=... -DSOURCE_DIR=... -DWORK_DIR=... [-DPYTHON=... -DPYTHON_DIR=...] -P check_package.cmake
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
function(step)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  message(STATUS "${out}")
endfunction()
step(${CMAKE_COMMAND} --install "${BUILD_DIR}" --prefix "${WORK_DIR}/prefix")
if(NOT EXISTS "${WORK_DIR}/prefix/bin/dvm")
  message(FATAL_ERROR "cmake --install put no dvm program in ${WORK_DIR}/prefix/bin")
endif()
step("${WORK_DIR}/prefix/bin/dvm" run "${SOURCE_DIR}/examples/scenes/pendulum.toml" --no-output --quiet)
step(${CMAKE_COMMAND} -S "${SOURCE_DIR}/examples/library" -B "${WORK_DIR}/build"
     -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix)
step(${CMAKE_COMMAND} --build "${WORK_DIR}/build")
step("${WORK_DIR}/build/kepler_composition")
if(PYTHON)
  if(NOT EXISTS "${WORK_DIR}/prefix/${PYTHON_DIR}/dvm/__init__.py")
    message(FATAL_ERROR "cmake --install put no Python package dvm in ${WORK_DIR}/prefix/${PYTHON_DIR}")
  endif()
  # (lines, not semicolons: a semicolon would split the argument as a CMake list)
  string(CONCAT code "import dvm, os\n"
         "assert os.path.dirname(dvm.__file__) == os.path.realpath('${WORK_DIR}/prefix/${PYTHON_DIR}/dvm'), dvm.__file__\n"
         "r = dvm.run(dvm.load_scene('${SOURCE_DIR}/examples/scenes/pendulum.toml'))\n"
         "assert r.status == 'ok' and r.steps == 10000 and r.q.shape == (1001, 1), r\n"
         "print('installed module:', r)\n")
  step(${CMAKE_COMMAND} -E env "PYTHONPATH=${WORK_DIR}/prefix/${PYTHON_DIR}" ${PYTHON} -c "${code}")
endif()
file(REMOVE_RECURSE "${WORK_DIR}")
