build2/obj/master/launch.o: master/launch.c master/launch.h \
 common/base/log.h
master/launch.h:
common/base/log.h:
