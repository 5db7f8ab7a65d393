scene corner1, database corner1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 2 | 3976 | 89.3 % | 96.4 % | 98.1 % | 0.24 | 3976 | 84.5 % | 94.8 % | 97.3 % |
| view0.png view2.png | 2 | 2775 | 75.8 % | 83.7 % | 90.0 % | 0.34 | 2775 | 67.4 % | 78.0 % | 81.1 % |
| view0.png view3.png | 2 | 1863 | 55.0 % | 63.2 % | 68.5 % | 0.71 | 1863 | 48.8 % | 57.8 % | 60.2 % |
| view0.png view4.png | 2 | 940 | 12.0 % | 14.5 % | 16.1 % | 121.30 | 940 | 11.1 % | 14.1 % | 15.1 % |
| view1.png view2.png | 2 | 4023 | 91.7 % | 96.8 % | 98.9 % | 0.21 | 4023 | 85.3 % | 94.5 % | 96.9 % |
| view1.png view3.png | 2 | 1285 | 73.9 % | 80.2 % | 82.0 % | 0.32 | 1285 | 68.1 % | 78.6 % | 81.3 % |
| view1.png view4.png | 2 | 1248 | 70.6 % | 76.4 % | 78.9 % | 0.39 | 1248 | 64.0 % | 74.8 % | 78.5 % |
| view2.png view3.png | 2 | 4233 | 85.9 % | 92.2 % | 96.1 % | 0.22 | 4233 | 79.8 % | 89.1 % | 91.1 % |
| view2.png view4.png | 6 | 2275 | 88.1 % | 96.3 % | 100.0 % | 0.24 | 2275 | 80.9 % | 93.4 % | 97.6 % |
| view3.png view4.png | 2 | 4173 | 86.7 % | 92.4 % | 94.5 % | 0.24 | 4173 | 80.8 % | 90.4 % | 92.4 % |
| all pairs |  | 26791 | 80.5 % | 87.0 % | 90.1 % | 0.28 | 26791 | 74.4 % | 84.2 % | 86.7 % |

model: 5/5 images registered, 6425 points
relative rotation error (every pair of images, no alignment): mean 0.055° max 0.101°
after a similarity alignment of the camera centres: centre error mean 0.0090 max 0.0177 (scene units), rotation error mean 0.300° max 0.345°
