build-san/obj/common/accel.o: common/accel.c common/accel.h \
 common/scene.h common/vec.h common/log.h common/motion.h
common/accel.h:
common/scene.h:
common/vec.h:
common/log.h:
common/motion.h:
