# `cmake --install` into a scratch prefix, then the installed trbc: a forward simulation, and a
# phase-1 inference whose provenance must name the installed experimental data and surrogates
# (<prefix>/share/trbc/data), not the source tree; then the installed CMake package, linked by
# examples/cmake_consumer.
# cmake -DBUILD_DIR=... -DSOURCE_DIR=... -DPREFIX=... -P check_install.cmake
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

# The libraries as a CMake package: examples/cmake_consumer, built outside the tree against the
# installed trbc, evaluates the membrane energy of a cell exported by the installed trbc; its terms
# must equal those of `trbc forces` on the same meshes and moduli.
set(cell ${PREFIX}/cell)
file(WRITE ${PREFIX}/samples.csv "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um\n0.93,4.66,2.26e-19,2.0,0.70\n0.92,4.60,2.20e-19,1.9,0.68\n0.94,4.70,2.30e-19,2.1,0.72\n")
execute_process(COMMAND ${trbc} export --posterior ${PREFIX}/samples.csv --level 2 --no-cache --out ${cell}
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "installed trbc export failed (${rc}):\n${err}")
endif()
set(consumer ${PREFIX}/consumer-build)
execute_process(COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR}/examples/cmake_consumer -B ${consumer}
                        -DCMAKE_PREFIX_PATH=${PREFIX} -DCMAKE_BUILD_TYPE=Release
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "configuring examples/cmake_consumer against ${PREFIX} failed:\n${out}\n${err}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${consumer} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "building examples/cmake_consumer failed:\n${out}\n${err}")
endif()
execute_process(COMMAND ${consumer}/membrane_energy ${cell} RESULT_VARIABLE rc OUTPUT_VARIABLE energy ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "membrane_energy ${cell} failed (${rc}):\n${err}")
endif()
file(READ ${cell}/cell.json cellJson)
string(JSON mu GET "${cellJson}" physical mu_uN_per_m)
string(JSON kb GET "${cellJson}" physical kb_J)
foreach(c a3 a4 b1 b2)
  string(JSON ${c} GET "${cellJson}" dimensionless ${c})
endforeach()
execute_process(COMMAND ${trbc} forces --mesh ${cell}/equilibrium.off --reference ${cell}/sfs.off --out ${PREFIX}/forces.csv
                        --kb ${kb} --ka ${mu}e-18 --mu ${mu}e-18 --a3 ${a3} --a4 ${a4} --b1 ${b1} --b2 ${b2}
                RESULT_VARIABLE rc OUTPUT_VARIABLE forces ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "installed trbc forces failed (${rc}):\n${err}")
endif()
foreach(term bending lim)
  string(JSON mine GET "${energy}" ${term}_J)
  string(JSON theirs GET "${forces}" terms ${term})
  if(mine LESS_EQUAL 0)
    message(FATAL_ERROR "membrane_energy: ${term} energy ${mine} J is not positive:\n${energy}")
  endif()
  # The same library code; the moduli differ in the last bit (mu * 1e-18 in the program, the decimal
  # text "<mu>e-18" for trbc forces): the first 11 significant digits and the exponent must agree.
  string(REGEX MATCH "^([0-9]\\.[0-9]+)e([-+][0-9]+)$" m1 "${mine}")
  set(mant1 ${CMAKE_MATCH_1})
  set(exp1 ${CMAKE_MATCH_2})
  string(REGEX MATCH "^([0-9]\\.[0-9]+)e([-+][0-9]+)$" m2 "${theirs}")
  set(mant2 ${CMAKE_MATCH_1})
  set(exp2 ${CMAKE_MATCH_2})
  string(SUBSTRING "${mant1}" 0 12 mant1)
  string(SUBSTRING "${mant2}" 0 12 mant2)
  if(NOT m1 OR NOT m2 OR NOT mant1 STREQUAL mant2 OR NOT exp1 STREQUAL exp2)
    message(FATAL_ERROR "membrane_energy ${term} = ${mine} J, trbc forces ${theirs} J")
  endif()
endforeach()
message(STATUS "examples/cmake_consumer: ${energy}")
