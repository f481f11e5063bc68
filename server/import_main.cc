// radiosity-import: reads one model through assimp in a process of its own (ModelImportMain).
#include "solver/input/model_loader.h"

int main(int argc, char** argv) { return radiosity::ModelImportMain(argc, argv); }
