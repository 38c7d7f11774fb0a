build-san/obj/tests/unit/test_camera.o: tests/unit/test_camera.c \
 common/camera.h common/sampler.h common/rng.h common/scene.h \
 common/vec.h
common/camera.h:
common/sampler.h:
common/rng.h:
common/scene.h:
common/vec.h:
