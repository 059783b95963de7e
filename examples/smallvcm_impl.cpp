// The one translation unit that compiles smallvcm's implementation part: the glTF
// loader (tinygltf) and the image writers (stb_image_write). Every program links it;
// it is compiled once (it is the slow one).
#define SMALLVCM_IMPLEMENTATION
#include "smallvcm.hpp"
