# `cmake --install` into a scratch prefix, then the installed trbc: a forward simulation, and a
# phase-1 inference whose provenance must name the installed experimental data and surrogates
# (<prefix>/share/trbc/data), not the source tree.
# cmake -DBUILD_DIR=... -DPREFIX=... -P check_install.cmake
cmake_minimum_required(VERSION 3.20)
file(REMOVE_RECURSE ${PREFIX})
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${PREFIX}
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cmake --install ${BUILD_DIR} --prefix ${PREFIX} failed:\n${err}")
endif()
# The environment's overrides of the data folders would hide what the lookup finds.
set(trbc ${CMAKE_COMMAND} -E env --unset=TRBC_DATA_DIR --unset=TRBC_SURROGATE_DIR --unset=TRBC_EXPERIMENT_DATA
    ${PREFIX}/bin/trbc)

execute_process(COMMAND ${trbc} simulate --level 2 --no-cache RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "installed trbc simulate failed (${rc}):\n${err}")
endif()
string(JSON status GET "${out}" status)
if(NOT status STREQUAL "ok")
  message(FATAL_ERROR "installed trbc simulate: status ${status}\n${out}")
endif()

execute_process(COMMAND ${trbc} infer --phase 1 --samples 200 --threads 1 --quiet --out ${PREFIX}/infer
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "installed trbc infer failed (${rc}):\n${err}")
endif()
file(READ ${PREFIX}/infer/infer.json provenance)
string(JSON data GET "${provenance}" data_dir)
string(JSON model GET "${provenance}" model dir)
file(REAL_PATH ${PREFIX}/share/trbc/data shipped)
foreach(used IN ITEMS "${data}" "${model}")
  string(FIND "${used}" "${shipped}/" at)
  if(NOT at EQUAL 0)
    message(FATAL_ERROR "installed trbc infer read ${used}, not the installed data under ${shipped}")
  endif()
endforeach()
