# ctest driver: install the built rayforge into a private prefix, then
# configure, build and run the consumer project and the examples/ programs
# against it, checking what each example prints and writes.
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})
function(run_step)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "step failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  message(STATUS "${out}")
endfunction()
run_step(${CMAKE_COMMAND} --install ${RAYFORGE_BUILD_DIR} --prefix ${WORK_DIR}/prefix)
run_step(${CMAKE_COMMAND} -S ${CONSUMER_SOURCE_DIR} -B ${WORK_DIR}/build
         -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix -DCMAKE_BUILD_TYPE=Release)
run_step(${CMAKE_COMMAND} --build ${WORK_DIR}/build)
run_step(${WORK_DIR}/build/consumer)

# The examples: only the installed public API.
run_step(${CMAKE_COMMAND} -S ${EXAMPLES_SOURCE_DIR} -B ${WORK_DIR}/examples
         -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix -DCMAKE_BUILD_TYPE=Release)
run_step(${CMAKE_COMMAND} --build ${WORK_DIR}/examples)
function(run_example expected)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "example failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  if(NOT out MATCHES "${expected}")
    message(FATAL_ERROR "example ${ARGN}: no match for '${expected}' in:\n${out}")
  endif()
  message(STATUS "${out}")
endfunction()
run_example("camera rays: 19200, hits: [0-9]+" ${WORK_DIR}/examples/trace_rays builtin:cornell cpu)
run_example("camera moved: 0 passes accumulated.*wrote .*progressive.png: 160x120, 4 passes"
            ${WORK_DIR}/examples/progressive_render ${WORK_DIR}/progressive.png 8 cpu)
if(NOT EXISTS ${WORK_DIR}/progressive.png)
  message(FATAL_ERROR "progressive_render wrote no image")
endif()
run_example("binned +[0-9.]+ +[0-9]+.*ploc +[0-9.]+ +[0-9]+" ${WORK_DIR}/examples/build_all builtin:spheres cpu)
run_example("frame 0: .*frame 10: .*frame 20: .*refit on cpu" ${WORK_DIR}/examples/animate ${WORK_DIR}/animate_ cpu)
foreach(frame 0 10 20)
  if(NOT EXISTS ${WORK_DIR}/animate_${frame}.png)
    message(FATAL_ERROR "animate wrote no animate_${frame}.png")
  endif()
endforeach()
run_example("wrote .*small.rfpack: [0-9]+ triangles.*rendered .*small.png.*geometry: [0-9]+ of [0-9]+ pages cached"
            ${WORK_DIR}/examples/paged ${WORK_DIR}/small.rfpack ${WORK_DIR}/small.png 100000)
