# Runs across machines (docs/mpi.md): a capture scene rendered by one process and by K MPI ranks writes
# the same bytes, and a failure on one rank stops every rank. Run by CTest (tests/CMakeLists.txt) as
#   cmake -DTPRF=... -DMPIEXEC=... "-DMPIEXEC_FLAGS=..." -DSCENE=... -DWORK=... -DMODE=... [-DRANKS=K]
#         -P render_ranks.cmake
# MODE one:   renders WORK/one with a plain `tprf render` (the reference; a CTest fixture).
# MODE ranks: renders WORK/ranksK with `mpirun -np K tprf render` and compares every output with
#             WORK/one byte for byte; render.json must record the K shares, contiguous, by whole batches.
# MODE stop:  rank 0 alone cannot write its output directory, then every rank reads a bad scene: both
#             times every rank stops with status 2 (no rank left waiting) and one error line is printed.
foreach(var TPRF MPIEXEC SCENE WORK MODE)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "render_ranks.cmake: ${var} is not set")
  endif()
endforeach()
separate_arguments(flags UNIX_COMMAND "${MPIEXEC_FLAGS}")
set(reference "${WORK}/one")

function(render out)  # render(OUT [mpirun args...]): ARGN empty: a plain run
  file(REMOVE_RECURSE "${out}")
  set(launcher)
  if(ARGN)
    set(launcher "${MPIEXEC}" ${flags} ${ARGN})
  endif()
  execute_process(COMMAND ${launcher} "${TPRF}" render "${SCENE}" -o "${out}" -q --threads 1
                  RESULT_VARIABLE rc ERROR_VARIABLE err OUTPUT_QUIET)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${launcher} tprf render ${SCENE} -o ${out}: exit ${rc}\n${err}")
  endif()
endfunction()

# Every file below DIR (hidden ones too: a staging folder left behind would show), relative to it.
function(files_below dir result)
  file(GLOB_RECURSE names LIST_DIRECTORIES true RELATIVE "${dir}" "${dir}/*")
  list(SORT names)
  set(${result} "${names}" PARENT_SCOPE)
endfunction()

function(json_get result json)
  string(JSON value GET "${json}" ${ARGN})
  set(${result} "${value}" PARENT_SCOPE)
endfunction()

# render.json of the K-rank run: the capture's totals as one process's, and K shares of laser points
# that follow each other from 0 to the last, each starting at a whole batch.
function(check_shares ranks_json one_json K)
  foreach(key batch marches link_bin_updates view_pairs laser_points)
    json_get(mine "${ranks_json}" capture ${key})
    json_get(theirs "${one_json}" capture ${key})
    if(NOT mine STREQUAL theirs)
      message(FATAL_ERROR "render.json capture.${key}: ${mine} with ${K} ranks, ${theirs} with one process")
    endif()
  endforeach()
  json_get(ranks "${ranks_json}" capture ranks)
  json_get(batch "${ranks_json}" capture batch)
  json_get(lasers "${ranks_json}" capture laser_points)
  if(NOT ranks EQUAL K)
    message(FATAL_ERROR "render.json capture.ranks: ${ranks}, expected ${K}")
  endif()
  set(next 0)
  math(EXPR last "${K} - 1")
  foreach(r RANGE ${last})
    json_get(first "${ranks_json}" capture shares ${r} laser_points 0)
    json_get(end "${ranks_json}" capture shares ${r} laser_points 1)
    math(EXPR offset "${first} % ${batch}")
    if(NOT first EQUAL next OR end LESS first OR NOT offset EQUAL 0)
      message(FATAL_ERROR "render.json capture.shares[${r}].laser_points [${first}, ${end}]: expected to start at "
                          "${next}, on a whole batch of ${batch}")
    endif()
    set(next ${end})
  endforeach()
  if(NOT next EQUAL lasers)
    message(FATAL_ERROR "render.json capture.shares end at laser point ${next} of ${lasers}")
  endif()
endfunction()

function(compare_with_reference out K)
  files_below("${reference}" expected)
  files_below("${out}" written)
  if(NOT written STREQUAL expected)
    message(FATAL_ERROR "${out} holds [${written}], one process wrote [${expected}]")
  endif()
  foreach(name IN LISTS expected)
    if(name STREQUAL "render.json" OR IS_DIRECTORY "${reference}/${name}")
      continue()
    endif()
    execute_process(COMMAND "${CMAKE_COMMAND}" -E compare_files "${reference}/${name}" "${out}/${name}"
                    RESULT_VARIABLE differ)
    if(NOT differ EQUAL 0)
      message(FATAL_ERROR "${name}: ${K} ranks wrote other bytes than one process")
    endif()
  endforeach()
  file(READ "${out}/render.json" ranks_json)
  file(READ "${reference}/render.json" one_json)
  check_shares("${ranks_json}" "${one_json}" ${K})
  list(LENGTH expected count)
  message(STATUS "${K} ranks: ${count} outputs, every one the same bytes as one process's")
endfunction()

# Runs `mpirun -np 2 tprf render SCENE -o OUT`, which must fail on every rank with one error line
# holding `words`.
function(expect_stop scene out words)
  execute_process(COMMAND "${MPIEXEC}" ${flags} -np 2 "${TPRF}" render "${scene}" -o "${out}" -q --threads 1
                  RESULT_VARIABLE rc ERROR_VARIABLE err OUTPUT_QUIET TIMEOUT 60)
  string(REGEX MATCHALL "tprf: error:[^\n]*" lines "${err}")
  list(LENGTH lines count)
  if(rc EQUAL 0 OR NOT count EQUAL 1 OR NOT err MATCHES "${words}")
    message(FATAL_ERROR "mpirun -np 2 tprf render ${scene} -o ${out}: exit ${rc}, ${count} error lines (expected "
                        "a failure and one line with '${words}'):\n${err}")
  endif()
  message(STATUS "stopped (exit ${rc}): ${lines}")
endfunction()

if(MODE STREQUAL "one")
  render("${reference}")
elseif(MODE STREQUAL "ranks")
  render("${WORK}/ranks${RANKS}" -np ${RANKS})
  compare_with_reference("${WORK}/ranks${RANKS}" ${RANKS})
elseif(MODE STREQUAL "stop")
  file(MAKE_DIRECTORY "${WORK}/stop")
  file(WRITE "${WORK}/stop/a-file" "")
  expect_stop("${SCENE}" "${WORK}/stop/a-file/out" "a-file/out: cannot write")
  file(WRITE "${WORK}/stop/bad.json" "{\"time\": {\"bins\": 0, \"bin_width\": 0.01}}")
  expect_stop("${WORK}/stop/bad.json" "${WORK}/stop/out" "bad.json: missing key")
else()
  message(FATAL_ERROR "render_ranks.cmake: MODE ${MODE}: one, ranks or stop")
endif()
