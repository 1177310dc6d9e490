# cmake -P script: the plug-in as an engine gets it. Copies libsoftshell_plugin alone into a fresh
# directory (as into Unity's Assets/Plugins), compiles a plain C program there with the C compiler
# directly (no CMake package: -I <prefix>/include and the one library), and runs it without
# LD_LIBRARY_PATH.
file(REMOVE_RECURSE ${DIR})
file(MAKE_DIRECTORY ${DIR})
file(COPY ${PREFIX}/lib/libsoftshell_plugin.so DESTINATION ${DIR})
separate_arguments(flags UNIX_COMMAND "${FLAGS}")
execute_process(COMMAND ${C_COMPILER} -std=c11 -Wall -Wextra -Werror ${flags} -I${PREFIX}/include ${SOURCE}
                        -o ${DIR}/program -L${DIR} -lsoftshell_plugin -lm "-Wl,-rpath,$ORIGIN"
                RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "compiling ${SOURCE} against the plug-in failed:\n${err}")
endif()
file(GLOB files RELATIVE ${DIR} ${DIR}/*)
execute_process(COMMAND ${CMAKE_COMMAND} -E env --unset=LD_LIBRARY_PATH ${DIR}/program
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${DIR}/program failed (${rc}):\n${out}\n${err}")
endif()
message(STATUS "${DIR} holds only ${files}; the program ran:\n${out}")
