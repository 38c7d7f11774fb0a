build-san/obj/common/camera.o: common/camera.c common/camera.h \
 common/sampler.h common/rng.h common/scene.h common/vec.h
common/camera.h:
common/sampler.h:
common/rng.h:
common/scene.h:
common/vec.h:
