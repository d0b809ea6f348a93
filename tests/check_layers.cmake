# The subsystems a layer's sources can include are exactly those docs/DESIGN.md allows: for every
# pair of layers (L, M), a source of L (L's include directories as the build uses them) that
# includes a header of M must preprocess when M is L or below it, and must fail otherwise.
# cmake -DCXX=... -DSOURCE_DIR=... -DINCLUDES=<generated file> -DWORK=<scratch dir> -P check_layers.cmake

cmake_minimum_required(VERSION 3.20)

# The allowed graph: each layer and the layers directly below it.
set(below_core "")
set(below_mesh core)
set(below_membrane mesh)
set(below_solvers membrane)
set(below_experiments solvers)
set(below_sampling experiments)
set(below_surrogate sampling)
set(below_inference surrogate)
set(below_flow sampling)
set(below_analysis inference flow)

function(layers_below layer out)
  set(all "")
  foreach(b IN LISTS below_${layer})
    layers_below(${b} deeper)
    list(APPEND all ${b} ${deeper})
  endforeach()
  list(REMOVE_DUPLICATES all)
  set(${out} ${all} PARENT_SCOPE)
endfunction()

include(${INCLUDES})  # layers: the layers the build defines; includes_<layer>: those of trbc_<layer>
foreach(layer IN LISTS layers)
  if(NOT DEFINED below_${layer})
    message(FATAL_ERROR "layer ${layer} is not in the graph of this test (docs/DESIGN.md)")
  endif()
endforeach()
file(MAKE_DIRECTORY ${WORK})
set(failures "")
foreach(layer IN LISTS layers)
  layers_below(${layer} allowed)
  list(APPEND allowed ${layer})
  set(flags "")
  foreach(dir IN LISTS includes_${layer})
    if(dir)  # an $<INSTALL_INTERFACE:...> entry is empty in the build tree
      list(APPEND flags -I${dir})
    endif()
  endforeach()
  foreach(other IN LISTS layers)
    file(GLOB headers RELATIVE ${SOURCE_DIR}/src ${SOURCE_DIR}/src/${other}/*.hpp)
    list(SORT headers)
    list(GET headers 0 header)
    set(probe ${WORK}/${layer}_includes_${other}.cpp)
    file(WRITE ${probe} "#include \"${header}\"\n")
    execute_process(COMMAND ${CXX} -std=c++20 -E ${flags} ${probe} -o ${WORK}/out.ii
                    RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
    if(other IN_LIST allowed AND NOT rc EQUAL 0)
      string(APPEND failures "${layer} cannot include ${header}, a layer it may use:\n${err}\n")
    elseif(NOT other IN_LIST allowed AND rc EQUAL 0)
      string(APPEND failures "${layer} can include ${header}, a layer above it or beside it\n")
    endif()
  endforeach()
endforeach()
if(failures)
  message(FATAL_ERROR "${failures}")
endif()
