# Runs a program and checks its exit status and its output, for ctest: a test with
# only PASS_REGULAR_EXPRESSION passes on matching output whatever the exit status.
#
#   cmake -DPROGRAM=path [-DARGS=a;b] -DPASS=regex [-DFAIL=regex] -P expect_output.cmake
#
# Fails (exit status 1) when the program does not exit with 0, when its standard output
# does not match PASS, or when it matches FAIL. The output is printed either way.
if(NOT DEFINED PROGRAM OR NOT DEFINED PASS)
  message(FATAL_ERROR "expect_output.cmake: PROGRAM and PASS are required")
endif()
execute_process(COMMAND "${PROGRAM}" ${ARGS} RESULT_VARIABLE status OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${out}${err}")
if(NOT status STREQUAL "0")
  message(FATAL_ERROR "${PROGRAM} ${ARGS}: exit status ${status}, expected 0")
endif()
if(NOT out MATCHES "${PASS}")
  message(FATAL_ERROR "${PROGRAM} ${ARGS}: the output does not match '${PASS}'")
endif()
if(DEFINED FAIL AND out MATCHES "${FAIL}")
  message(FATAL_ERROR "${PROGRAM} ${ARGS}: the output matches '${FAIL}' (${CMAKE_MATCH_0})")
endif()
